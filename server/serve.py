"""`retarget serve`: the app on a real port, and who can reach it.

On loopback (the default) only this machine reaches the server and no token is needed.
On any other address the whole network does, so an access token is required
(`server.access`): made on first start, kept in the data directory, and printed within
the address to open, which hands it to the page.
"""

from __future__ import annotations

import socket
from pathlib import Path

from server.access import Access, is_loopback, token_for

__all__ = ["serve", "startup_message"]


def startup_message(host: str, port: int, access: Access, data_dir: Path) -> str:
    """What `serve` prints: the address to open, who can reach it, where projects are."""
    shown = f"[{host}]" if ":" in host else host
    if access.token is None:
        return (f"retarget server: http://{shown}:{port}/ (API docs at /docs), projects in "
                f"{data_dir.resolve()}\nOnly this machine can reach it (listening on {host}).")
    if host.strip("[]") in ("0.0.0.0", "::", ""):
        shown = socket.gethostname()  # or any of its IP addresses
    return (f"retarget server: http://{shown}:{port}/?token={access.token}\n"
            f"Listening on {host}: every machine that can reach this one on port {port} can "
            "connect, and those given the address above (it holds the access token) can read, "
            "change and delete the projects. Keep the token secret; it is kept in "
            f"{data_dir.resolve() / 'access-token'} (delete that file and restart for a new "
            f"one). API clients send 'Authorization: Bearer <token>'. Projects in "
            f"{data_dir.resolve()}.")


def serve(data_dir: Path, *, host: str = "127.0.0.1", port: int = 8000,
          allowed_hosts: tuple[str, ...] = (), token: bool = False, **app_options) -> None:
    """Run the app with uvicorn until interrupted.

    allowed_hosts : more Host names to answer to (a DNS name the machine is reached by).
    token : require the access token on loopback too (it is always required elsewhere).
    app_options : `create_app` limits (max_upload_bytes, max_vertices, max_video_frames).
    """
    import uvicorn

    from server.app import UVICORN_OPTIONS, create_app

    data_dir = Path(data_dir)
    data_dir.mkdir(parents=True, exist_ok=True)
    needs_token = token or not is_loopback(host)
    access = Access.for_bind(host, token=token_for(data_dir) if needs_token else None,
                             allowed_hosts=allowed_hosts)
    app = create_app(data_dir, access=access, **app_options)
    print(startup_message(host, port, access, data_dir), flush=True)
    uvicorn.run(app, host=host, port=port, log_level="info", **UVICORN_OPTIONS)
