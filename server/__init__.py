"""The retarget web server: a FastAPI app over the `retarget` library (`create_app`).

Kept apart from the library: `retarget` never imports this package.
"""
