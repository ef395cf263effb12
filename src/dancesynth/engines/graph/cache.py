"""Build a style's meta motion graph once, keep it on disk, reload it in milliseconds.

The cache key covers the style's content fingerprint, the graph parameters, the graph
format version and the graph builder's own source, so a changed database, parameter
or algorithm rebuilds the graph.
"""

from __future__ import annotations

import hashlib
import zipfile
from dataclasses import fields
from pathlib import Path

import numpy as np

from ...io.files import atomic_output
from ...motion import accents
from ...motion.database import Style, cache_dir
from . import meta_graph
from .meta_graph import GRAPH_FORMAT_VERSION, GraphConfig, MetaMotionGraph, build_graph

_SCALARS = ("style", "fps", "thr", "n_forced", "n_trapped")


# The code that builds graphs (and finds the accents they render) is part of the key:
# editing it can never serve a stale graph.
_BUILDER = hashlib.blake2b(Path(meta_graph.__file__).read_bytes() + Path(accents.__file__).read_bytes(),
                           digest_size=8).hexdigest()


def graph_path(style: Style, config: GraphConfig, root: Path | None = None) -> Path:
    key = hashlib.blake2b(
        f"{GRAPH_FORMAT_VERSION}|{_BUILDER}|{style.name}|{style.fingerprint}|{config.key()}".encode(),
        digest_size=16).hexdigest()
    return (root or cache_dir()) / "graphs" / f"{style.name}-{key}.npz"


def load_graph(style: Style, config: GraphConfig = GraphConfig(), *, use_cache: bool = True) -> tuple[MetaMotionGraph, bool]:
    """The graph of ``style``; returns ``(graph, came_from_cache)``."""
    path = graph_path(style, config)
    if use_cache and style.fingerprint and path.is_file():
        try:
            with np.load(path, allow_pickle=False) as z:
                data = {k: z[k] for k in z.files}
            kwargs = {f.name: data[f.name] for f in fields(MetaMotionGraph) if f.name in data}
            for k in _SCALARS:
                kwargs[k] = kwargs[k].item()
            return MetaMotionGraph(**kwargs), True
        except (OSError, ValueError, KeyError, TypeError, EOFError, zipfile.BadZipFile):
            pass  # unreadable cache entry: rebuild below
    graph = build_graph(style, config)
    if use_cache and style.fingerprint:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            with atomic_output(path, "wb") as fh:
                np.savez(fh, **graph.arrays(), **{k: np.array(getattr(graph, k)) for k in _SCALARS})
        except OSError:
            pass  # a read-only cache only costs the rebuild next time
    return graph, False
