"""The browser client's files: the page, its modules, the GLSL shaders and the npm
packages installed by ``npm ci --prefix web`` (served from here, never from a CDN).

    /                      web/static/index.html
    /static/...            web/static/
    /shaders/...           web/shaders/
    /vendor/<package>/...  web/node_modules/<package>/  (only the packages in VENDORED;
                           @mediapipe/face_mesh tracks the live webcam in the page; video
                           files are tracked on the server, `retarget.facemesh`)
    /docs                  the OpenAPI docs, Swagger UI from the npm package swagger-ui-dist
"""

from __future__ import annotations

import base64
import hashlib
import re
from pathlib import Path

from fastapi import FastAPI
from fastapi.openapi.docs import get_swagger_ui_html
from fastapi.responses import FileResponse, HTMLResponse
from fastapi.staticfiles import StaticFiles

from server import WEB_DIR

__all__ = ["VENDORED", "WEB_DIR", "app_csp", "mount_web"]

VENDORED = ("three", "three-mesh-bvh", "swagger-ui-dist", "@mediapipe/face_mesh")

def app_csp(page: str) -> str:
    """The app page's Content-Security-Policy: its own scripts (and, by hash, the inline
    ones `page` has: the import map), its own connections (the stream's WebSocket is
    'self' too), nothing framed, no plugins."""
    inline = re.findall(r"<script(?![^>]*\bsrc=)[^>]*>(.*?)</script>", page, flags=re.DOTALL)
    hashes = " ".join(f"'sha256-{base64.b64encode(hashlib.sha256(s.encode()).digest()).decode()}'"
                      for s in inline)
    return "; ".join((
        "default-src 'self'",
        # MediaPipe's face mesh compiles its WebAssembly in the page, and its loader
        # evaluates strings as JavaScript (an EvalError without 'unsafe-eval'); scripts
        # still come from this server only
        f"script-src 'self' 'wasm-unsafe-eval' 'unsafe-eval' {hashes}".strip(),
        "style-src 'self' 'unsafe-inline'",
        "img-src 'self' data: blob:",
        "media-src 'self' mediastream:",  # the webcam's stream: videos are tracked on the server
        "connect-src 'self' data: blob:",
        "worker-src 'self' blob:",
        "object-src 'none'",
        "base-uri 'none'",
        "form-action 'self'",
        "frame-ancestors 'none'",
    ))


_DOCS_CSP = ("default-src 'self'; script-src 'self' 'unsafe-inline'; style-src 'self' 'unsafe-inline'; "
             "img-src 'self' data:; frame-ancestors 'none'")

_MISSING = """<!doctype html><meta charset="utf-8"><title>retarget: front-end packages missing</title>
<h1>The browser client's packages are not installed</h1>
<p>{missing} not found under <code>{node_modules}</code>. Install them with
<code>npm ci --prefix web</code> (the README's run command does this) and reload.</p>"""


def mount_web(app: FastAPI, web_dir: Path = WEB_DIR) -> None:
    """Serve the client from `web_dir`. When the npm packages are missing the page says
    how to install them (HTTP 503) instead of failing on a blank screen.

    The app must be made with ``docs_url=None``: FastAPI's own /docs loads Swagger UI
    from a CDN; this one serves it from `web_dir`."""
    node_modules = web_dir / "node_modules"
    missing = [name for name in VENDORED if not (node_modules / name / "package.json").is_file()]
    index = web_dir / "static" / "index.html"
    csp = app_csp(index.read_text(encoding="utf-8"))

    @app.get("/", include_in_schema=False, response_model=None)
    def index_page() -> FileResponse | HTMLResponse:
        if missing:
            return HTMLResponse(_MISSING.format(missing=", ".join(missing), node_modules=node_modules),
                                status_code=503)
        return FileResponse(index, headers={"Cache-Control": "no-cache",
                                            "Content-Security-Policy": csp})

    @app.get("/docs", include_in_schema=False, response_model=None)
    def docs_page() -> HTMLResponse:
        if "swagger-ui-dist" in missing:
            return HTMLResponse(_MISSING.format(missing="swagger-ui-dist", node_modules=node_modules),
                                status_code=503)
        page = get_swagger_ui_html(openapi_url=app.openapi_url, title=f"{app.title} API",
                                   swagger_js_url="/vendor/swagger-ui-dist/swagger-ui-bundle.js",
                                   swagger_css_url="/vendor/swagger-ui-dist/swagger-ui.css",
                                   swagger_favicon_url="/vendor/swagger-ui-dist/favicon-32x32.png")
        page.headers["Content-Security-Policy"] = _DOCS_CSP
        return page

    app.mount("/static", StaticFiles(directory=web_dir / "static"), name="static")
    app.mount("/shaders", StaticFiles(directory=web_dir / "shaders", check_dir=False), name="shaders")
    for name in VENDORED:
        if name not in missing:
            app.mount(f"/vendor/{name}", StaticFiles(directory=node_modules / name), name=f"vendor-{name}")
