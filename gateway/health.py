"""System health samples (LLD §8.2 system_health): CPU, memory, disk, GPU if any, temperature if any."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import psutil


def gpu_sample() -> tuple[float | None, float | None]:
    """(utilisation %, memory used MB) of the first NVIDIA GPU, or (None, None) without one."""
    exe = shutil.which("nvidia-smi")
    if exe is None:
        return None, None
    try:
        out = subprocess.run(
            [exe, "--query-gpu=utilization.gpu,memory.used", "--format=csv,noheader,nounits"],
            capture_output=True,
            text=True,
            timeout=2.0,
            check=True,
        ).stdout.splitlines()[0]
        util, mem = (float(v) for v in out.split(","))
        return util, mem
    except (subprocess.SubprocessError, OSError, ValueError, IndexError):
        return None, None


def temperature_celsius() -> float | None:
    """The hottest reported sensor, or None where the platform reports none."""
    read = getattr(psutil, "sensors_temperatures", None)
    if read is None:
        return None
    try:
        sensors = read()
    except (OSError, RuntimeError):
        return None
    temps = [t.current for entries in sensors.values() for t in entries if t.current and t.current > 0]
    return max(temps) if temps else None


def sample(disk_path: Path, with_gpu: bool = True) -> dict[str, float | None]:
    """One sample as the system_health columns. ``cpu_percent`` is since the previous call."""
    gpu_util, gpu_mem = gpu_sample() if with_gpu else (None, None)
    return {
        "cpu_percent": float(psutil.cpu_percent(interval=None)),
        "memory_percent": float(psutil.virtual_memory().percent),
        "disk_percent": float(psutil.disk_usage(str(disk_path)).percent),
        "gpu_percent": gpu_util,
        "gpu_memory_mb": gpu_mem,
        "temperature_celsius": temperature_celsius(),
    }
