"""Per-trial variation of the twin's world (pure: numpy + dataclasses, no MuJoCo).

A :class:`Variation` is what one trial's world is really like: the rod's size and mass, the frictions,
the table height, the gripper force, the drive's tracking and latency, the camera's true mount and
intrinsics, its depth noise and the light. :func:`sample_variation` draws it from the ranges in
``sim.twin.randomization``, seeded from the trial's seed (on its own stream, so the scene layout of a seed
is the same with and without randomization); :func:`nominal_variation` is the configured world itself.
Only the twin reads it — the cell keeps its nominal models, calibration and intrinsics.

:meth:`Variation.record` flattens it into named scalars in human units for the eval's JSON, and
:func:`record_ranges` gives the range of each of those scalars, so the eval can bin its outcomes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from services.common.settings import TwinSceneSettings, TwinSettings
from services.common.settings.sim import TwinRandomizationSettings
from services.sim.twin.noise import HIGHLIGHT_GAIN

Array = np.ndarray

RANDOMIZATION_STREAM = 0x19  # SeedSequence([seed, stream]): independent of the scene layout's draws


@dataclass(frozen=True)
class Variation:
    randomized: bool
    rod_diameter_m: float
    rod_length_m: float
    rod_mass_kg: float
    pad_friction: float
    rod_table_friction: float
    table_height_m: float  # table top above the robot base plane (nominal 0)
    grip_force_n: float
    tracking_bandwidth_rad_s: float
    command_latency_s: float
    camera_offset_m: tuple[float, float, float]  # true camera position − nominal, base frame
    camera_rotation_deg: tuple[float, float, float]  # true vs. nominal, rotation vector in the camera frame
    focal_scale: float  # true focal length / the reported one
    principal_offset_px: tuple[float, float]  # true principal point − the reported one (u, v)
    depth_subpixel: float
    hole_fraction: float
    light_scale: float
    highlight_gain: float

    def scene_settings(self, scene: TwinSceneSettings) -> TwinSceneSettings:
        """The scene section with this world's rod (the layout then fits the true rod)."""
        return scene.model_copy(
            update={
                "rod_diameter_m": self.rod_diameter_m,
                "rod_length_m": self.rod_length_m,
                "rod_mass_kg": self.rod_mass_kg,
            }
        )

    def camera_rotation(self) -> Array:
        """R_nominal_true: the true camera axes in the nominal camera frame."""
        return Rotation.from_rotvec(np.deg2rad(self.camera_rotation_deg)).as_matrix()

    def record(self) -> dict[str, float]:
        """Named scalars in human units (mm, g, ms, %, px) for the eval's JSON and its sensitivity table."""
        off = np.asarray(self.camera_offset_m) * 1000.0
        rot = np.asarray(self.camera_rotation_deg)
        return {
            "rod_diameter_mm": round(self.rod_diameter_m * 1000.0, 4),
            "rod_length_mm": round(self.rod_length_m * 1000.0, 4),
            "rod_mass_g": round(self.rod_mass_kg * 1000.0, 3),
            "pad_friction": round(self.pad_friction, 4),
            "rod_table_friction": round(self.rod_table_friction, 4),
            "table_height_mm": round(self.table_height_m * 1000.0, 3),
            "grip_force_n": round(self.grip_force_n, 3),
            "tracking_bandwidth_rad_s": round(self.tracking_bandwidth_rad_s, 3),
            "command_latency_ms": round(self.command_latency_s * 1000.0, 3),
            "camera_offset_x_mm": round(float(off[0]), 3),
            "camera_offset_y_mm": round(float(off[1]), 3),
            "camera_offset_z_mm": round(float(off[2]), 3),
            "camera_offset_mm": round(float(np.linalg.norm(off)), 3),
            "camera_rot_x_deg": round(float(rot[0]), 4),
            "camera_rot_y_deg": round(float(rot[1]), 4),
            "camera_rot_z_deg": round(float(rot[2]), 4),
            "camera_rotation_deg": round(float(np.linalg.norm(rot)), 4),
            "focal_error_pct": round((self.focal_scale - 1.0) * 100.0, 4),
            "principal_offset_u_px": round(self.principal_offset_px[0], 3),
            "principal_offset_v_px": round(self.principal_offset_px[1], 3),
            "depth_subpixel": round(self.depth_subpixel, 4),
            "hole_fraction": round(self.hole_fraction, 4),
            "light_scale": round(self.light_scale, 4),
            "highlight_gain": round(self.highlight_gain, 4),
        }


def nominal_variation(twin: TwinSettings) -> Variation:
    """The configured world, unvaried."""
    p, sc, cam = twin.physics, twin.scene, twin.camera
    return Variation(
        randomized=False,
        rod_diameter_m=sc.rod_diameter_m,
        rod_length_m=sc.rod_length_m,
        rod_mass_kg=sc.rod_mass_kg,
        pad_friction=p.pad_friction,
        rod_table_friction=p.object_friction,
        table_height_m=0.0,
        grip_force_n=p.grip_force_n,
        tracking_bandwidth_rad_s=p.tracking_bandwidth_rad_s,
        command_latency_s=0.0,
        camera_offset_m=(0.0, 0.0, 0.0),
        camera_rotation_deg=(0.0, 0.0, 0.0),
        focal_scale=1.0,
        principal_offset_px=(0.0, 0.0),
        depth_subpixel=cam.depth_subpixel,
        hole_fraction=cam.hole_fraction,
        light_scale=1.0,
        highlight_gain=HIGHLIGHT_GAIN,
    )


def sample_variation(twin: TwinSettings, seed: int) -> Variation:
    """This seed's world: every value uniform in its range of ``twin.randomization`` (see the module doc)."""
    r = twin.randomization
    p, sc = twin.physics, twin.scene
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), RANDOMIZATION_STREAM]))

    def u(rng_range: tuple[float, float]) -> float:
        return float(rng.uniform(*rng_range))

    def u3(rng_range: tuple[float, float]) -> tuple[float, float, float]:
        a, b, c = (float(x) for x in rng.uniform(*rng_range, size=3))
        return (a, b, c)

    diameter = sc.rod_diameter_m + u(r.rod_diameter_delta_m)
    diameter = max(diameter, 2 * sc.rod_wall_m + 1e-4)  # a tube keeps its bore
    return Variation(
        randomized=True,
        rod_diameter_m=diameter,
        rod_length_m=sc.rod_length_m + u(r.rod_length_delta_m),
        rod_mass_kg=sc.rod_mass_kg * u(r.rod_mass_scale),
        pad_friction=u(r.pad_friction),
        rod_table_friction=u(r.rod_table_friction),
        table_height_m=u(r.table_height_delta_m),
        grip_force_n=p.grip_force_n * u(r.grip_force_scale),
        tracking_bandwidth_rad_s=p.tracking_bandwidth_rad_s * u(r.tracking_bandwidth_scale),
        command_latency_s=u(r.command_latency_s),
        camera_offset_m=u3(r.camera_offset_m),
        camera_rotation_deg=u3(r.camera_rotation_deg),
        focal_scale=u(r.focal_scale),
        principal_offset_px=(u(r.principal_offset_px), u(r.principal_offset_px)),
        depth_subpixel=u(r.depth_subpixel),
        hole_fraction=u(r.hole_fraction),
        light_scale=u(r.light_scale),
        highlight_gain=u(r.highlight_gain),
    )


def variation_for(twin: TwinSettings, seed: int) -> Variation:
    """Randomized when ``twin.randomization.enabled``, else the nominal world."""
    return sample_variation(twin, seed) if twin.randomization.enabled else nominal_variation(twin)


def record_ranges(twin: TwinSettings) -> dict[str, tuple[float, float]]:
    """The range each :meth:`Variation.record` scalar is drawn from (same units), for binning."""
    r: TwinRandomizationSettings = twin.randomization
    p, sc = twin.physics, twin.scene

    def shifted(nominal: float, rng: tuple[float, float], k: float = 1000.0) -> tuple[float, float]:
        return ((nominal + rng[0]) * k, (nominal + rng[1]) * k)

    def scaled(nominal: float, rng: tuple[float, float], k: float = 1.0) -> tuple[float, float]:
        return (nominal * rng[0] * k, nominal * rng[1] * k)

    off_mm = (r.camera_offset_m[0] * 1000.0, r.camera_offset_m[1] * 1000.0)
    off_max = float(np.sqrt(3.0) * max(abs(off_mm[0]), abs(off_mm[1])))
    rot_max = float(np.sqrt(3.0) * max(abs(r.camera_rotation_deg[0]), abs(r.camera_rotation_deg[1])))
    return {
        "rod_diameter_mm": shifted(sc.rod_diameter_m, r.rod_diameter_delta_m),
        "rod_length_mm": shifted(sc.rod_length_m, r.rod_length_delta_m),
        "rod_mass_g": scaled(sc.rod_mass_kg, r.rod_mass_scale, 1000.0),
        "pad_friction": r.pad_friction,
        "rod_table_friction": r.rod_table_friction,
        "table_height_mm": shifted(0.0, r.table_height_delta_m),
        "grip_force_n": scaled(p.grip_force_n, r.grip_force_scale),
        "tracking_bandwidth_rad_s": scaled(p.tracking_bandwidth_rad_s, r.tracking_bandwidth_scale),
        "command_latency_ms": shifted(0.0, r.command_latency_s),
        "camera_offset_x_mm": off_mm,
        "camera_offset_y_mm": off_mm,
        "camera_offset_z_mm": off_mm,
        "camera_offset_mm": (0.0, off_max),
        "camera_rot_x_deg": r.camera_rotation_deg,
        "camera_rot_y_deg": r.camera_rotation_deg,
        "camera_rot_z_deg": r.camera_rotation_deg,
        "camera_rotation_deg": (0.0, rot_max),
        "focal_error_pct": ((r.focal_scale[0] - 1.0) * 100.0, (r.focal_scale[1] - 1.0) * 100.0),
        "principal_offset_u_px": r.principal_offset_px,
        "principal_offset_v_px": r.principal_offset_px,
        "depth_subpixel": r.depth_subpixel,
        "hole_fraction": r.hole_fraction,
        "light_scale": r.light_scale,
        "highlight_gain": r.highlight_gain,
    }
