"""The retarget web server: a FastAPI app over the `retarget` library (`create_app`).

Kept apart from the library: `retarget` never imports this package.
"""

from pathlib import Path

__all__ = ["WEB_DIR"]

WEB_DIR = Path(__file__).resolve().parent.parent / "web"
"""The browser client's files (`server.web` serves them). Here, not in `server.web`, so
the command line (`server.cli`) names it without importing the web stack: every isolated
child re-runs the main module, as multiprocessing does, and would import it again."""
