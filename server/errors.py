"""Every refusal is an HTTP 4xx (or 503 when busy) whose body is ``{"detail": "<what is
wrong>"}``, one shape for all, and the OpenAPI schema says so.

`install(app)` maps the library's and the store's exceptions to statuses, turns FastAPI's
request validation errors (a list of dicts) into one sentence, answers 405 with the
``Allow`` header of every method the schema has for the path (Starlette names only the
first route's), and documents the answers: `responses(*codes)` is what a router declares.
"""

from __future__ import annotations

import re

from fastapi import FastAPI, Request, status
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from pydantic import BaseModel
from starlette.exceptions import HTTPException as StarletteHTTPException

from retarget.errors import RetargetError
from server.isolation import IsolationBusy
from server.store import ProjectNotFound, StaleRig, TakeNotFound

__all__ = ["Error", "install", "responses"]


class Error(BaseModel):
    """A refusal: what is wrong with the request, in words."""

    detail: str


_MEANINGS = {
    400: "the request is malformed (bad JSON, a bad header, a Host this server does not answer to)",
    401: "the server needs its access token (it listens beyond this machine)",
    403: "the request comes from another web page",
    404: "no such project, take or job",
    405: "the path does not take this method (Allow lists those it takes)",
    409: "the project is not ready for this, or changed since (a running job, a stale rig)",
    413: "the request body or an uploaded file is over the server's limit",
    415: "the uploaded file's type is not one this route reads",
    422: "the request or its file is refused; detail says why",
    503: "the server is busy reading other files; try again shortly",
}
ALWAYS = (400, 401, 403, 413, 422)
"""What any API route may answer: malformed request, token, origin, body size, refusal."""


def responses(*codes: int) -> dict[int, dict]:
    """OpenAPI answers of a route (or router) beside `ALWAYS`: each code with `Error`."""
    return {code: {"model": Error, "description": _MEANINGS[code]}
            for code in sorted(set(ALWAYS) | set(codes))}


def _sentence(errors) -> str:
    """FastAPI's validation errors as one sentence naming each field."""
    places = {"body": "body field", "query": "query parameter", "path": "path parameter",
              "header": "header", "cookie": "cookie"}
    parts = []
    for error in errors:
        loc = [str(part) for part in error.get("loc", ())]
        if loc and loc[0] in places:
            place, loc = places[loc[0]], loc[1:]
        else:  # a model validated from the body by the route itself
            place = "body field"
        message = error.get("msg", "invalid")
        parts.append(f"{place} {'.'.join(loc)!r}: {message}" if loc else f"body: {message}")
    return "; ".join(parts) or "the request is invalid"


def install(app: FastAPI) -> None:
    """Register the exception handlers and the OpenAPI error schema on `app`."""

    def handler(code: int):
        async def answer(request: Request, exc: Exception) -> JSONResponse:
            return JSONResponse({"detail": str(exc)}, code)
        return answer

    app.add_exception_handler(RetargetError, handler(422))
    app.add_exception_handler(ProjectNotFound, handler(status.HTTP_404_NOT_FOUND))
    app.add_exception_handler(TakeNotFound, handler(status.HTTP_404_NOT_FOUND))
    app.add_exception_handler(StaleRig, handler(status.HTTP_409_CONFLICT))
    app.add_exception_handler(IsolationBusy, handler(status.HTTP_503_SERVICE_UNAVAILABLE))

    async def invalid(request: Request, exc: RequestValidationError) -> JSONResponse:
        return JSONResponse({"detail": _sentence(exc.errors())}, 422)

    async def http_error(request: Request, exc: StarletteHTTPException) -> JSONResponse:
        headers = dict(exc.headers or {})
        if exc.status_code == 405:
            headers["Allow"] = ", ".join(_allowed(request))
        detail = exc.detail if isinstance(exc.detail, str) else str(exc.detail)
        cause = exc.__cause__
        if exc.status_code == 400 and cause is not None:  # FastAPI's "error parsing the body"
            detail = ("the request body is nested too deeply to read"
                      if isinstance(cause, RecursionError) else
                      f"the request body could not be read: {type(cause).__name__}: {cause}"[:300])
        return JSONResponse({"detail": detail}, exc.status_code, headers=headers)

    async def too_deep(request: Request, exc: RecursionError) -> JSONResponse:
        # only input nests this deep: a JSON body or field read in the server process
        return JSONResponse({"detail": "the request is nested too deeply to read"}, 422)

    app.add_exception_handler(RecursionError, too_deep)
    app.add_exception_handler(RequestValidationError, invalid)
    app.add_exception_handler(StarletteHTTPException, http_error)

    def openapi() -> dict:
        if app.openapi_schema is None:
            schema = FastAPI.openapi(app)
            for path in schema.get("paths", {}).values():
                for operation in path.values():
                    for code, answer in operation.get("responses", {}).items():
                        if code == "422":  # FastAPI's own list-of-errors schema: not ours
                            answer["content"] = {"application/json": {
                                "schema": {"$ref": "#/components/schemas/Error"}}}
                            answer["description"] = _MEANINGS[422]
            for name in ("HTTPValidationError", "ValidationError"):
                schema.get("components", {}).get("schemas", {}).pop(name, None)
            app.openapi_schema = schema
        return app.openapi_schema

    app.openapi = openapi


def _allowed(request: Request) -> list[str]:
    """The methods the app's schema lists for the request's path, from its most specific
    path templates (``/api/projects/import`` before ``/api/projects/{project_id}``, as the
    routes are matched); a GET route answers HEAD too."""
    matching = []
    for template, operations in request.app.openapi().get("paths", {}).items():
        pattern = re.sub(r"\\\{[^/]+?\\\}", "[^/]+", re.escape(template))
        if re.fullmatch(pattern, request.url.path):
            matching.append((template.count("{"), {m.upper() for m in operations}))
    fewest = min((n for n, _ in matching), default=0)
    methods = set().union(*(m for n, m in matching if n == fewest))
    if "GET" in methods:
        methods.add("HEAD")
    return sorted(methods)
