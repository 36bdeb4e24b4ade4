"""Generate the Python code for ``proto/`` (``make proto``) and check it is current."""

from __future__ import annotations

import filecmp
import sys
import tempfile
from pathlib import Path

PROTO_ROOT = Path(__file__).resolve().parents[2] / "proto"
PACKAGE_DIR = PROTO_ROOT / "pickplace" / "v1"


def proto_files() -> list[Path]:
    return sorted(PACKAGE_DIR.glob("*.proto"))


def generate(out_dir: Path) -> list[Path]:
    """Run protoc (from grpcio-tools) over every .proto into ``out_dir``; return generated files."""
    from grpc_tools import protoc

    out_dir.mkdir(parents=True, exist_ok=True)
    files = [str(p.relative_to(PROTO_ROOT)) for p in proto_files()]
    args = [
        "protoc",
        f"-I{PROTO_ROOT}",
        f"--python_out={out_dir}",
        f"--grpc_python_out={out_dir}",
        f"--pyi_out={out_dir}",
        *files,
    ]
    if protoc.main(args) != 0:
        raise RuntimeError(f"protoc failed: {' '.join(args)}")
    return sorted((out_dir / "pickplace" / "v1").glob("*_pb2*.py*"))


def stale_files() -> list[str]:
    """Names of generated files that differ from what protoc produces now (empty = in sync)."""
    with tempfile.TemporaryDirectory() as tmp:
        fresh = generate(Path(tmp))
        stale = []
        for f in fresh:
            committed = PACKAGE_DIR / f.name
            if not committed.exists() or not filecmp.cmp(f, committed, shallow=False):
                stale.append(f.name)
        fresh_names = {f.name for f in fresh}
        stale += [p.name for p in PACKAGE_DIR.glob("*_pb2*.py*") if p.name not in fresh_names]
        return stale


def main() -> int:
    generate(PROTO_ROOT)
    print(f"generated Python for {len(proto_files())} proto files in {PACKAGE_DIR}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
