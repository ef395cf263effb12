"""A web page to watch the character dance: ``dancesynth serve`` (Starlette + uvicorn, imported lazily)."""
