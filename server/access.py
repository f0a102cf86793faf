"""Who may drive the server: the Host it is reached by, the page a request comes from,
and, beyond this machine, an access token.

The API has no accounts, so three other web pages' tricks must be stopped at the door:

- **DNS rebinding**: a page on ``evil.example`` whose name is made to resolve to
  127.0.0.1 reaches the server as its own origin. Its requests carry
  ``Host: evil.example``, so a request whose Host name is not one the server was started
  on (`Access.hosts`) is refused (400). An IP literal cannot be rebound, so a server
  listening on every interface accepts any IP literal plus the machine's names.
- **Cross-site request forgery and WebSocket hijacking**: a page on another origin can
  send a form POST or open a WebSocket to 127.0.0.1 with the user's browser. Browsers
  mark such requests with ``Origin`` (and ``Sec-Fetch-Site``), so a request that changes
  state (any method but GET, HEAD, OPTIONS) or opens a WebSocket is refused (403) when
  its Origin is not the server's own. Clients that are not browsers send no Origin and
  are not affected.
- **Other machines**: listening on anything but loopback lets the whole network in, so
  it needs an access token (`Access.token`, `token_for`): on /api, /docs and the page,
  as the ``retarget_token`` cookie, an ``Authorization: Bearer`` header or a ``token``
  query parameter. Opening the printed ``/?token=...`` address sets the cookie
  (HttpOnly, SameSite=Strict) and redirects to ``/``, so the page keeps it and its
  fetches and WebSockets carry it without a line of client code.

Every HTTP answer also gets ``X-Content-Type-Options: nosniff``, frame denial and
``Referrer-Policy: no-referrer``; the app page's Content-Security-Policy is set where the
page is served (`server.web`).
"""

from __future__ import annotations

import ipaddress
import json
import os
import secrets
import socket
from dataclasses import dataclass
from http.cookies import SimpleCookie
from pathlib import Path
from urllib.parse import parse_qs, urlsplit

__all__ = ["Access", "AccessGuard", "IN_PROCESS_NAMES", "LOOPBACK_NAMES", "TOKEN_COOKIE", "is_loopback", "token_for"]

LOOPBACK_NAMES = frozenset({"localhost", "127.0.0.1", "::1"})
IN_PROCESS_NAMES = LOOPBACK_NAMES | {"testserver"}
"""The default of an app made in-process (`create_app` without `access`): loopback, and
the name Starlette's TestClient sends (no DNS resolves it, so a page cannot be rebound to
it). `retarget serve` answers to `Access.for_bind`'s names only."""
TOKEN_COOKIE = "retarget_token"
TOKEN_FILE = "access-token"
_SAFE_METHODS = frozenset({"GET", "HEAD", "OPTIONS"})
_PUBLIC_PREFIXES = ("/static/", "/shaders/", "/vendor/")  # the client's code, no data
SECURITY_HEADERS = (
    (b"x-content-type-options", b"nosniff"),
    (b"x-frame-options", b"DENY"),
    (b"referrer-policy", b"no-referrer"),
    (b"cross-origin-resource-policy", b"same-origin"),
)


def is_loopback(host: str) -> bool:
    """Whether listening on `host` (an address or name) reaches this machine only."""
    if host.lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def token_for(data_dir: Path) -> str:
    """The server's access token, made on first use and kept in ``<data_dir>/access-token``
    (readable by its owner only), so the printed address stays valid across restarts."""
    path = Path(data_dir) / TOKEN_FILE
    try:
        token = path.read_text().strip()
        if len(token) >= 32:
            return token
    except FileNotFoundError:
        pass
    path.parent.mkdir(parents=True, exist_ok=True)
    token = secrets.token_urlsafe(32)
    with os.fdopen(os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600), "w") as out:
        out.write(token + "\n")
    return token


@dataclass(frozen=True)
class Access:
    """The server's access rules.

    hosts : Host names (lower case, no port, IPv6 without brackets) requests may carry.
    any_ip : accept any IP literal as Host as well (a server on every interface).
    token : required on everything but the client's static files when set.
    """

    hosts: frozenset[str] = IN_PROCESS_NAMES
    any_ip: bool = False
    token: str | None = None

    @classmethod
    def for_bind(cls, host: str, *, token: str | None = None,
                 allowed_hosts: tuple[str, ...] = ()) -> "Access":
        """The rules for a server listening on `host`: loopback names for a loopback
        address; otherwise that address (any IP literal for 0.0.0.0 or ::) and the
        machine's names. `token` is required off loopback (refused when missing)."""
        extra = {_host_name(h) for h in allowed_hosts}
        if is_loopback(host):
            return cls(LOOPBACK_NAMES | extra, token=token)
        if token is None:
            raise ValueError(f"listening on {host!r} reaches other machines: an access token "
                             "is required")
        names = {socket.gethostname().lower(), socket.getfqdn().lower(), _host_name(host)}
        wildcard = host.strip("[]") in ("0.0.0.0", "::", "")
        return cls(frozenset(LOOPBACK_NAMES | names | extra), any_ip=wildcard, token=token)

    def host_allowed(self, host_header: str | None) -> bool:
        if not host_header:
            return False
        name = _host_name(host_header)
        if name in self.hosts:
            return True
        if self.any_ip:
            try:
                ipaddress.ip_address(name)
                return True
            except ValueError:
                return False
        return False

    def token_matches(self, given: str | None) -> bool:
        return self.token is None or (given is not None and
                                      secrets.compare_digest(given.encode(), self.token.encode()))


def _host_name(host: str) -> str:
    """The name part of a Host header or address: no port, no IPv6 brackets, lower case."""
    host = host.strip().lower()
    if host.startswith("["):
        return host[1:host.find("]")] if "]" in host else host[1:]
    if host.count(":") == 1:
        return host.split(":", 1)[0]
    return host


class AccessGuard:
    """ASGI middleware enforcing `Access` on HTTP requests and WebSocket handshakes
    (module docstring), and adding the security headers to every HTTP answer."""

    def __init__(self, app, access: Access):
        self.app, self.access = app, access

    async def __call__(self, scope, receive, send):
        if scope["type"] not in ("http", "websocket"):
            return await self.app(scope, receive, send)
        headers = _headers(scope)
        refusal = self._refusal(scope, headers)
        if refusal is not None:
            status, detail = refusal
            if scope["type"] == "websocket":
                # before accept: the server answers the handshake with HTTP 403
                return await send({"type": "websocket.close", "code": 1008, "reason": detail[:120]})
            return await _answer(send, status, {"detail": detail})
        if scope["type"] == "websocket":
            return await self.app(scope, receive, send)
        query = parse_qs(scope.get("query_string", b"").decode("latin-1"))
        if self.access.token is not None and scope["path"] == "/" and "token" in query:
            return await self._welcome(send, query["token"][0])

        async def secured(message):
            if message["type"] == "http.response.start":
                present = {name.lower() for name, _ in message.get("headers", [])}
                extra = [h for h in SECURITY_HEADERS if h[0] not in present]
                message = {**message, "headers": [*message.get("headers", []), *extra]}
            await send(message)

        return await self.app(scope, receive, secured)

    def _refusal(self, scope, headers: dict[str, str]) -> tuple[int, str] | None:
        """(status, reason) when the request must be refused, else None."""
        host = headers.get("host")
        if not self.access.host_allowed(host):
            return 400, (f"this server does not answer to the host name {host!r}: open it by "
                         "the address it printed when it started")
        unsafe = scope["type"] == "websocket" or scope.get("method", "GET") not in _SAFE_METHODS
        if unsafe and not _same_origin(scope, headers):
            return 403, (f"refused: a request from another web page "
                         f"({headers.get('origin') or headers.get('sec-fetch-site')}) may not "
                         "change this server's projects or open its stream")
        path = scope["path"]
        if self.access.token is not None and not path.startswith(_PUBLIC_PREFIXES):
            if not self.access.token_matches(_token(scope, headers)):
                if path == "/" and "token" in parse_qs(scope.get("query_string", b"").decode("latin-1")):
                    return None  # `_welcome` checks it and says what is wrong
                return 401, ("this server needs its access token: open the address with "
                             "?token=... that it printed when it started, or send "
                             "'Authorization: Bearer <token>'")
        return None

    async def _welcome(self, send, given: str) -> None:
        """``/?token=...``: a good token becomes the page's cookie (then a redirect to
        ``/`` so it leaves the address bar and history); a wrong one is refused."""
        if not self.access.token_matches(given):
            return await _answer(send, 401, {"detail": "wrong access token: copy the address the "
                                             "server printed when it started"})
        cookie = SimpleCookie()
        cookie[TOKEN_COOKIE] = given
        cookie[TOKEN_COOKIE].update({"httponly": True, "samesite": "Strict", "path": "/"})
        await send({"type": "http.response.start", "status": 303, "headers": [
            (b"location", b"/"), (b"set-cookie", cookie[TOKEN_COOKIE].OutputString().encode()),
            (b"content-length", b"0"), (b"cache-control", b"no-store"), *SECURITY_HEADERS]})
        await send({"type": "http.response.body", "body": b""})


def _headers(scope) -> dict[str, str]:
    return {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope.get("headers", [])}


def _same_origin(scope, headers: dict[str, str]) -> bool:
    """Whether a browser request comes from the server's own page. No Origin and no
    Sec-Fetch-Site: not a browser's cross-site request (curl, the CLI, tests)."""
    site = headers.get("sec-fetch-site")
    if site is not None and site not in ("same-origin", "none"):
        return False
    origin = headers.get("origin")
    if origin is None:
        return True
    scheme = "https" if scope.get("scheme") in ("https", "wss") else "http"
    return origin != "null" and _origin(origin) == _origin(f"{scheme}://{headers.get('host', '')}")


def _origin(url: str) -> tuple[str, str, int | None] | None:
    """(scheme, host name, port with the scheme's default) of an origin, None if malformed."""
    parts = urlsplit(url)
    try:
        port = parts.port
    except ValueError:
        return None
    if not parts.hostname:
        return None
    return parts.scheme, parts.hostname.lower(), port or {"http": 80, "https": 443}.get(parts.scheme)


def _token(scope, headers: dict[str, str]) -> str | None:
    auth = headers.get("authorization", "")
    if auth.lower().startswith("bearer "):
        return auth[7:].strip()
    cookie = SimpleCookie()
    try:
        cookie.load(headers.get("cookie", ""))
    except Exception:  # noqa: BLE001 - a malformed cookie header is no token
        return None
    if TOKEN_COOKIE in cookie:
        return cookie[TOKEN_COOKIE].value
    query = parse_qs(scope.get("query_string", b"").decode("latin-1"))
    return query.get("token", [None])[0]


async def _answer(send, status: int, body: dict) -> None:
    data = json.dumps(body).encode()
    await send({"type": "http.response.start", "status": status, "headers": [
        (b"content-type", b"application/json"), (b"content-length", str(len(data)).encode()),
        *SECURITY_HEADERS]})
    await send({"type": "http.response.body", "body": data})
