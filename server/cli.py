"""The installed ``retarget`` command: the library's commands (`retarget.cli`) and ``serve``.

The library's command line never imports the web stack; this one adds ``serve`` (the web
app on a real port, `server.serve`) to the library's parser. ``python -m server.cli`` runs
it from a checkout. It imports no web stack itself either: multiprocessing re-runs it in
every isolated child (`server.isolation`).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from retarget.cli import build_parser as library_parser, main as run
from retarget.cli.parser import PROG, positive_float, positive_int
from retarget.errors import RetargetError

__all__ = ["build_parser", "main"]

SERVE_DATA_DIR = "retarget-data"


def build_parser() -> argparse.ArgumentParser:
    """The library's parser with ``serve`` added."""
    parser = library_parser()
    p = parser.commands.add_parser(
        "serve", help="run the web server",
        description="Serve the web app and its REST API (docs at /docs); projects are kept in "
        "--data-dir across restarts.")
    p.add_argument("--host", default="127.0.0.1",
                   help="address to listen on (default: 127.0.0.1, this machine only; any other "
                   "address needs the access token the server prints)")
    p.add_argument("--allowed-host", action="append", default=[], metavar="NAME",
                   help="another host name the server is reached by (repeatable); requests "
                   "naming other hosts are refused")
    p.add_argument("--token", action="store_true",
                   help="require the access token on loopback too")
    p.add_argument("--port", type=_port, default=8000, help="port (default: 8000)")
    p.add_argument("--data-dir", default=SERVE_DATA_DIR, metavar="DIR",
                   help=f"project store folder, created if missing (default: ./{SERVE_DATA_DIR})")
    p.add_argument("--max-upload-mb", type=positive_float, metavar="MB",
                   help="largest uploaded file (mesh, take, video, .glb), MiB (default: 64)")
    p.add_argument("--max-vertices", type=positive_int, metavar="V",
                   help="most vertices an uploaded mesh may have (default: 500000)")
    p.add_argument("--max-video-frames", type=positive_int, metavar="F",
                   help="most frames of a video tracked markerless (default: 18000, 10 min at "
                   "30 fps)")
    p.set_defaults(run=_serve, quiet=True)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the ``retarget`` command line; returns the exit status (0, or 2 on error)."""
    return run(argv, parser=build_parser())


def _serve(args) -> int:
    try:
        from server.serve import serve
    except ImportError as exc:
        raise RetargetError(
            f"'{PROG} serve' needs the web server's packages ({exc.name} is missing): "
            "pip install fastapi 'uvicorn[standard]' python-multipart"
        ) from exc
    limits = {}  # flags not given keep the app's defaults
    if args.max_upload_mb is not None:
        limits["max_upload_bytes"] = int(args.max_upload_mb * 2**20)
    if args.max_vertices is not None:
        limits["max_vertices"] = args.max_vertices
    if args.max_video_frames is not None:
        limits["max_video_frames"] = args.max_video_frames
    serve(Path(args.data_dir), host=args.host, port=args.port,
          allowed_hosts=tuple(args.allowed_host), token=args.token, **limits)
    return 0


def _port(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a port number, got {text!r}") from None
    if not 0 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"expected a port in [0, 65535], got {value}")
    return value


if __name__ == "__main__":
    raise SystemExit(main())
