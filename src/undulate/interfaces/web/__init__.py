"""The web page (``undulate serve``): draw lines, see the prediction, run simulations.

Needs the ``web`` extra (``pip install 'undulate[web]'``: FastAPI and uvicorn).
"""

from __future__ import annotations

__all__ = ["create_app"]


def create_app(*args, **kwargs):  # noqa: ANN002, ANN003, ANN201 - see app.create_app
    """The FastAPI application (:func:`undulate.interfaces.web.app.create_app`)."""
    from .app import create_app as _create

    return _create(*args, **kwargs)
