"""The server the stream bench measures, in its own process: ``python -m benchmarks.stream_server``.

The bench (:mod:`benchmarks.stream`) starts it as a child so that its memory (RSS) is the server's alone and
its clients do not share the server's interpreter, as browsers would not: the furnace comes as JSON
(``FurnaceConfig.model_dump_json``), the app is the real one with the real loop factory, on
127.0.0.1 without the viser and rerun views.
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--config-json", required=True, help="file holding FurnaceConfig.model_dump_json()")
    p.add_argument("--data-dir", required=True)
    p.add_argument("--port", type=int, required=True)
    p.add_argument("--max-runs", type=int, default=3)
    p.add_argument("--switch-interval", type=float, default=None, help="sys.setswitchinterval (s), for A/B tests")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="%(asctime)s %(levelname)s %(name)s: %(message)s")

    import uvicorn

    from backend.app import create_app
    from backend.core.settings import Settings
    from backend.runs.loop_factory import DefaultLoopFactory
    from twin.config import FurnaceConfig

    if args.switch_interval:
        import sys

        sys.setswitchinterval(args.switch_interval)
    cfg = FurnaceConfig.model_validate_json(Path(args.config_json).read_text())
    settings = Settings(data_dir=Path(args.data_dir), port=args.port, viser_port=0, rerun_web_port=0,  # type: ignore[call-arg]
                        max_concurrent_runs=args.max_runs)
    app = create_app(settings, cfg, loop_factory=DefaultLoopFactory(settings))
    uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=args.port, log_level="warning")).run()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
