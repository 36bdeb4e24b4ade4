"""The Prometheus metrics of pickplace (LLD §8.1), named in one place.

Every service builds a :class:`CellMetrics` on its own :class:`CollectorRegistry`
(never the process-global default, so two services in one process — ``pickplace up``
— or in one test do not collide). In multi-process deployments (``PROMETHEUS_MULTIPROC_DIR``
set, one process per service) the values are written to that directory by each process
and :func:`exposition_registry` aggregates them for whichever process serves ``/metrics``.

Names follow Prometheus conventions: base units in the name (``_seconds``, ``_radians``),
``_total`` on counters (added by prometheus-client), low-cardinality labels.
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Sequence
from typing import Final

from prometheus_client import REGISTRY, CollectorRegistry, Counter, Gauge, Histogram, generate_latest
from prometheus_client import multiprocess as prom_multiprocess
from prometheus_client.metrics_core import Metric

MULTIPROC_ENV = "PROMETHEUS_MULTIPROC_DIR"

# Cycle times of a pick-and-place cell: seconds to a minute.
CYCLE_TIME_BUCKETS_S = (2.0, 4.0, 6.0, 8.0, 10.0, 12.0, 15.0, 20.0, 30.0, 45.0, 60.0, 120.0)
# Vision and planning: milliseconds to seconds (LLD §16.1 latency budget).
LATENCY_BUCKETS_S = (0.005, 0.01, 0.025, 0.05, 0.1, 0.2, 0.3, 0.5, 1.0, 2.0, 5.0, 10.0)
# In multi-process mode gauges need an aggregation rule; "mostrecent" keeps the newest value.
LIVE_GAUGE_MODE: Final = "mostrecent"


def multiprocess_dir() -> str | None:
    return os.environ.get(MULTIPROC_ENV) or None


class CellMetrics:
    """The LLD metric set on one registry. Services use the parts that concern them."""

    def __init__(self, registry: CollectorRegistry | None = None):
        self.registry = registry if registry is not None else CollectorRegistry(auto_describe=True)
        r = self.registry
        self.pick_success = Counter(
            "pick_success", "Successful picks", ["robot_id", "object_class"], registry=r
        )
        self.pick_failure = Counter(
            "pick_failure", "Failed picks", ["robot_id", "object_class", "stage"], registry=r
        )
        self.cycle_time = Histogram(
            "cycle_time_seconds",
            "Pick-place cycle time",
            ["robot_id"],
            buckets=CYCLE_TIME_BUCKETS_S,
            registry=r,
        )
        self.grasp_quality = Gauge(
            "grasp_quality",
            "Quality score [0, 1] of the latest executed grasp",
            ["robot_id"],
            registry=r,
            multiprocess_mode=LIVE_GAUGE_MODE,
        )
        self.vision_latency = Histogram(
            "vision_latency_seconds",
            "Vision pipeline latency per stage",
            ["stage"],  # detect | pose_estimate | total
            buckets=LATENCY_BUCKETS_S,
            registry=r,
        )
        self.planning_latency = Histogram(
            "planning_latency_seconds",
            "Motion/grasp planning latency per planner",
            ["planner"],
            buckets=LATENCY_BUCKETS_S,
            registry=r,
        )
        self.joint_position = Gauge(
            "robot_joint_position_radians",
            "Measured joint position",
            ["robot_id", "joint"],
            registry=r,
            multiprocess_mode=LIVE_GAUGE_MODE,
        )
        self.robot_mode = Gauge(
            "robot_mode",
            "Dobot RobotMode code (5 = enabled idle, 7 = running, 9 = error)",
            ["robot_id"],
            registry=r,
            multiprocess_mode=LIVE_GAUGE_MODE,
        )
        self.estop = Counter(
            "emergency_stop", "Emergency stops requested", ["robot_id", "source"], registry=r
        )
        self.picks_persisted = Counter("picks_persisted", "Pick events written to the database", registry=r)
        self.pick_buffer_depth = Gauge(
            "pick_buffer_depth",
            "Pick events waiting for the database",
            registry=r,
            multiprocess_mode=LIVE_GAUGE_MODE,
        )
        # the simulated controller: sim seconds per wall second it achieved (below its --speed when the
        # machine is too busy: it slows its clock rather than drop ticks), and the ticks that came late
        self.sim_clock_speed = Gauge(
            "sim_clock_speed_ratio",
            "Sim time per wall time the simulated controller achieved over the last window",
            registry=r,
            multiprocess_mode=LIVE_GAUGE_MODE,
        )
        self.sim_late_ticks = Counter(
            "sim_clock_late_ticks",
            "Simulated controller ticks that started after their wall time",
            registry=r,
        )

    def observe_pick(
        self,
        robot_id: str,
        object_class: str,
        success: bool,
        cycle_time_s: float,
        grasp_quality: float | None,
        stage: str = "",
    ) -> None:
        obj = object_class or "unknown"
        if success:
            self.pick_success.labels(robot_id, obj).inc()
            if cycle_time_s > 0:
                self.cycle_time.labels(robot_id).observe(cycle_time_s)
        else:
            self.pick_failure.labels(robot_id, obj, stage or "unknown").inc()
        if grasp_quality is not None and grasp_quality > 0:
            self.grasp_quality.labels(robot_id).set(grasp_quality)

    def set_joint_positions(
        self, robot_id: str, names: Sequence[str], positions_rad: Sequence[float]
    ) -> None:
        for name, q in zip(names, positions_rad, strict=False):
            self.joint_position.labels(robot_id, name).set(q)


def exposition_registry(own: CollectorRegistry) -> CollectorRegistry:
    """The registry ``/metrics`` should render: every process's values in multi-process mode, else ``own``."""
    path = multiprocess_dir()
    if path is None:
        return own
    agg = CollectorRegistry()
    prom_multiprocess.MultiProcessCollector(agg, path=path)
    return agg


# Every series a cell exports carries these two, whichever service made it.
CELL_LABEL: Final = "cell_id"
ROBOT_LABEL: Final = "robot_id"


class _Labelled:
    """A collector giving every sample of ``sources`` the cell's labels: ``cell_id``, and ``robot_id``
    set to the configured robot id (a pick event's own robot_id, the task's cell id, is overridden:
    one robot, one value). A family is taken from the first source that has samples of it, so two
    registries defining the same family (every service's CellMetrics) do not export it twice."""

    def __init__(self, sources: Sequence[CollectorRegistry], labels: dict[str, str]):
        self.sources = sources
        self.labels = labels

    def collect(self) -> Iterator[Metric]:
        chosen: dict[str, Metric] = {}  # in first-seen order; a family with samples wins over an empty one
        for source in self.sources:
            for family in source.collect():
                if family.name not in chosen or (family.samples and not chosen[family.name].samples):
                    chosen[family.name] = family
        for family in chosen.values():
            # an empty family is still declared (HELP/TYPE): a counter nothing has counted yet, such as
            # the e-stops of a cell that never stopped, is a series the dashboards may query
            out = Metric(family.name, family.documentation, family.type, family.unit)
            out.samples = [s._replace(labels={**s.labels, **self.labels}) for s in family.samples]
            yield out


def labelled_registry(
    own: CollectorRegistry,
    *,
    cell_id: str,
    robot_id: str,
    extra: Sequence[CollectorRegistry] = (),
    with_process_default: bool = True,
) -> CollectorRegistry:
    """What a cell's ``/metrics`` renders: ``own`` (every process's values in multi-process mode), then
    ``extra`` registries of services in this process, then prometheus-client's default registry (the
    module-level metrics of the motion and grasp services when they share the process), all with
    ``cell_id`` and ``robot_id`` on every series."""
    sources = [exposition_registry(own), *extra]
    if with_process_default and multiprocess_dir() is None:
        sources.append(REGISTRY)
    out = CollectorRegistry(auto_describe=False)
    out.register(_Labelled(sources, {CELL_LABEL: cell_id, ROBOT_LABEL: robot_id}))
    return out


def render(own: CollectorRegistry, registry: CollectorRegistry | None = None) -> bytes:
    """Prometheus text exposition of ``registry`` if given (a :func:`labelled_registry`), else of
    ``own`` (or of every process, in multi-process mode)."""
    return generate_latest(registry if registry is not None else exposition_registry(own))
