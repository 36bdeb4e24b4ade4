"""A Zenoh router for the compose smoke test: eclipse-zenoh's session in router mode, from a config file.

Usage: ``zenoh_router.py -c /etc/zenoh/zenoh.json5`` (the arguments eclipse/zenoh's ``zenohd`` takes).
"""

from __future__ import annotations

import argparse
import signal
import threading

import zenoh


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("-c", "--config", required=True)
    args = parser.parse_args()
    config = zenoh.Config.from_file(args.config)
    config.insert_json5("mode", '"router"')
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    with zenoh.open(config) as session:
        print(f"zenoh router {session.zid()} listening per {args.config}", flush=True)
        stop.wait()


if __name__ == "__main__":
    main()
