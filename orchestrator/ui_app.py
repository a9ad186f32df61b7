"""Provides the MLflow server app `linkevo ui` serves: MLflow's own (its FastAPI app, the one
`mlflow ui` runs), with the runs table's page raised from the 100 runs the MLflow UI asks
for to `RUNS_PAGE`, so every trial of a grid lands on the first page instead of a first
100 and a "Load more" button.

It is registered as the MLflow app plugin `linkevo` (the `mlflow.app` entry point in
pyproject.toml; MLflow's basic-auth app is the other such plugin) and run with
`mlflow ui --app-name linkevo`, so MLflow starts and configures it as it does its own.
"""

from __future__ import annotations

import json
from collections.abc import Awaitable, Callable
from typing import Any

UI_PAGE = 100
"""The runs the MLflow UI's runs table asks for per page (a constant of its bundle)."""
RUNS_PAGE = 2000
"""The runs each of those pages gets here: the study's grid at 30 trials is 420."""
SEARCH_PATH = "/mlflow/runs/search"

Scope = dict[str, Any]
Receive = Callable[[], Awaitable[dict[str, Any]]]
Send = Callable[[dict[str, Any]], Awaitable[None]]


class LargerRunsPage:
    """ASGI middleware: a runs search asking for `UI_PAGE` runs asks for `RUNS_PAGE`."""

    def __init__(self, app: Callable[[Scope, Receive, Send], Awaitable[None]]) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if (
            scope["type"] != "http"
            or scope["method"] != "POST"
            or not scope["path"].endswith(SEARCH_PATH)
        ):
            await self.app(scope, receive, send)
            return
        body, more = b"", True
        while more:
            message = await receive()
            body += message.get("body", b"")
            more = message.get("more_body", False)
        body = larger_page(body)
        headers = [(k, v) for k, v in scope["headers"] if k.lower() != b"content-length"]
        scope = {**scope, "headers": [*headers, (b"content-length", str(len(body)).encode())]}
        replayed = False

        async def replay() -> dict[str, Any]:
            nonlocal replayed
            if replayed:
                return await receive()
            replayed = True
            return {"type": "http.request", "body": body, "more_body": False}

        await self.app(scope, replay, send)


def larger_page(body: bytes) -> bytes:
    """Returns a runs-search request body with `max_results` raised to `RUNS_PAGE` where it
    asks for the UI's page; any other body as it is."""
    try:
        request = json.loads(body)
    except ValueError:
        return body
    if not isinstance(request, dict) or request.get("max_results") != UI_PAGE:
        return body
    return json.dumps({**request, "max_results": RUNS_PAGE}).encode()


def _app():
    from mlflow.server.fastapi_app import app as mlflow_app

    return LargerRunsPage(mlflow_app)


def __getattr__(name: str):
    # `app` is built when the server imports it, not when linkevo's tests import this module.
    if name == "app":
        return _app()
    raise AttributeError(name)
