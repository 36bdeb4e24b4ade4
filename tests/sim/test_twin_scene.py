"""The scene sampler: every seed gives a scene (only the sampler here, no physics)."""

import numpy as np
import pytest

from services.common.errors import InvalidInputError
from services.common.settings import load_settings
from services.sim.twin.scene import sample_scene

SIM_SCENE = load_settings("sim").sim.twin.scene


def _footprints_apart(scene) -> bool:  # type: ignore[no-untyped-def]
    """Cubes' centres apart by their size at least and inside the pick zone (a cheap layout check)."""
    lo, hi = np.asarray(SIM_SCENE.pick_zone_min_m), np.asarray(SIM_SCENE.pick_zone_max_m)
    xy = [np.asarray(o.position_m[:2]) for o in scene.objects]
    inside = all(np.all(p >= lo) and np.all(p <= hi) for p in xy)
    cubes = [np.asarray(o.position_m[:2]) for o in scene.objects if o.kind == "cube"]
    apart = all(
        np.linalg.norm(a - b) >= SIM_SCENE.cube_size_m for i, a in enumerate(cubes) for b in cubes[i + 1 :]
    )
    return inside and apart


def test_every_seed_gives_a_scene_with_every_object():
    names = {"rod", *(f"cube_{c}" for c in SIM_SCENE.cubes)} if SIM_SCENE.rod else set()
    redrawn = []
    for seed in range(2000):
        scene = sample_scene(SIM_SCENE, seed)
        assert {o.name for o in scene.objects} == names, seed
        assert _footprints_apart(scene), seed
        if scene.layout_redraws:
            redrawn.append(seed)
    # ≈0.3 % of seeds need a redraw (none of these 2000 with the sim profile): the first draw stays
    # the scene of every seed whose first draw fits
    assert len(redrawn) < 40, redrawn


def test_a_seed_whose_first_layout_fails_is_redrawn_reproducibly():
    a, b = sample_scene(SIM_SCENE, 848484), sample_scene(SIM_SCENE, 848484)
    assert a.layout_redraws >= 1 and a == b


def test_an_impossible_layout_still_says_why():
    tiny = SIM_SCENE.model_copy(update={"pick_zone_min_m": (0.40, 0.0), "pick_zone_max_m": (0.45, 0.05)})
    with pytest.raises(InvalidInputError, match="cannot place"):
        sample_scene(tiny, 1)
