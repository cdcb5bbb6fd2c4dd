"""Continuity features and block clusterings (Arikan, Forsyth & O'Brien 2003, Secs. 3.2-3.3).

* :func:`pca_features`: ``F(f)``, the PCA projection (``dims``, about 20) of each frame's body-joint
  positions, velocities and accelerations in its torso frame. Each group is divided by its RMS
  over the database (accelerations then weighted 0.5: they are the noisiest), and the projection is
  scaled so the median distance between two random database frames is :data:`CUT_SCALE`. The
  continuity cost of a cut from frame ``i`` to frame ``j`` is ``C = ||F(i + 1) - F(j)||`` (zero when
  ``j = i + 1``), so with ``alpha = 0.5`` a cut between unrelated poses costs as much as 15 output
  frames missing one requested label, and a cut between near-identical poses almost nothing.
* :func:`cluster_blocks`: for each block size ``B`` (32, 16, 8 frames), every run of ``B`` frames
  inside one clip (a block may start at any frame) is embedded as the features of 4 of its frames
  plus its mean label vector (weighted, so blocks that differ in their labels fall in different
  clusters: the stratified active sets then cover the vocabulary), and clustered by k-means:
  ``coarse_clusters`` clusters at the top level, ``blocks / blocks_per_cluster`` at finer levels
  (past :data:`MAX_FLAT_CLUSTERS` clusters, in two stages: :func:`two_stage_kmeans`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
import numpy.typing as npt
from sklearn.cluster import MiniBatchKMeans

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]

CUT_SCALE = 30.0
"""Median continuity cost (before ``1 - alpha``) of a cut between two random database frames."""

GROUP_WEIGHTS = (1.0, 1.0, 0.5)
"""Weights of positions, velocities and accelerations in the continuity features."""

PROJECT_ROWS = 16_384
"""Frames :func:`pca_features` projects at a time (bounds its working memory)."""


def pca_features(
    raw: FloatArray, dims: int, seed: int = 0, sample: int = 20_000
) -> tuple[npt.NDArray[np.float32], FloatArray, FloatArray]:
    """Continuity features ``F(f)``.

    Parameters
    ----------
    raw: ``(F, 3, D)`` positions (m), velocities (m/s), accelerations (m/s^2) in the torso frame.
    dims: output dimension (at most ``3 * D`` and ``F``).

    Returns
    -------
    features: ``(F, dims)`` float32, centred and scaled (see :data:`CUT_SCALE`).
    mean: ``(3 * D,)`` the centring of the normalized input.
    components: ``(dims, 3 * D)`` projection rows, including the group normalization and scale.
    """
    n = raw.shape[0]
    centred = raw - raw.mean(axis=0, keepdims=True)
    rms = np.sqrt(np.multiply(centred, centred, out=centred).mean(axis=(0, 2)))  # per group
    del centred
    weights = np.asarray(GROUP_WEIGHTS) / np.maximum(rms, 1e-12)
    x = (raw * weights[None, :, None]).reshape(n, -1)
    mean = x.mean(axis=0)
    rng = np.random.default_rng(seed)
    pick = rng.choice(n, size=min(n, sample), replace=False) if n > sample else np.arange(n)
    xs = x[pick] - mean
    k = max(1, min(dims, xs.shape[0], xs.shape[1]))
    comp = principal_axes(xs, k)
    feats = np.empty((n, k), dtype=np.float64)
    for r0 in range(0, n, PROJECT_ROWS):  # a chunk at a time: no (F, 3 D) temporary
        feats[r0 : r0 + PROJECT_ROWS] = (x[r0 : r0 + PROJECT_ROWS] - mean) @ comp.T
    a = rng.integers(0, n, size=4000)
    b = rng.integers(0, n, size=4000)
    med = float(np.median(np.linalg.norm(feats[a] - feats[b], axis=1)))
    s = CUT_SCALE / med if med > 0 else 1.0
    full = comp * s * np.repeat(weights, raw.shape[2])[None, :]
    return (feats * s).astype(np.float32), mean, full


def principal_axes(x: FloatArray, k: int) -> FloatArray:
    """``(k, D)`` the leading principal axes of centred rows ``x (N, D)`` (eigenvectors of the
    ``(D, D)`` scatter matrix, largest eigenvalue first)."""
    vals, vecs = np.linalg.eigh(x.T @ x)
    return np.asarray(vecs[:, ::-1][:, :k].T)


def next_features(features: npt.NDArray[np.float32], counts: Sequence[int]) -> npt.NDArray[np.float32]:
    """``(F, d)`` the features of the frame after each frame, ``F(f + 1)``; at a clip's last frame,
    linearly extrapolated (``2 F(f) - F(f - 1)``)."""
    out = np.empty_like(features)
    out[:-1] = features[1:]
    ends = np.cumsum(np.asarray(counts, dtype=np.intp)) - 1
    for e, n in zip(ends, counts, strict=True):
        out[e] = 2 * features[e] - features[e - 1] if n >= 2 else features[e]
    return out


def block_starts(counts: Sequence[int], size: int) -> IntArray:
    """``(N,)`` database frames where a block of ``size`` frames fits inside its clip."""
    starts = []
    offset = 0
    for n in counts:
        if n >= size:
            starts.append(np.arange(offset, offset + n - size + 1, dtype=np.intp))
        offset += n
    return np.concatenate(starts) if starts else np.zeros(0, dtype=np.intp)


def block_embedding(
    features: npt.NDArray[np.float32],
    labels: npt.NDArray[np.int8],
    starts: IntArray,
    size: int,
    label_weight: float,
) -> npt.NDArray[np.float32]:
    """``(N, 4 * d + L)`` block coordinates: the features of 4 evenly spaced frames of each block,
    and its mean label vector times ``label_weight * CUT_SCALE``."""
    offs = np.unique(np.round(np.linspace(0, size - 1, 4)).astype(np.intp))
    parts = [features[starts + o] for o in offs]
    if labels.shape[1]:
        c = np.cumsum(np.concatenate((np.zeros((1, labels.shape[1])), labels.astype(np.float64))), axis=0)
        mean = (c[starts + size] - c[starts]) / size
        parts.append((mean * (label_weight * CUT_SCALE)).astype(np.float32))
    return np.concatenate(parts, axis=1).astype(np.float32)


MAX_FLAT_CLUSTERS = 1024
"""A finer level with more clusters than this (over ~100k blocks) is clustered in two stages:
one k-means into ``N`` blocks' worth of clusters costs ``O(N * k)`` with ``k ~ N / 100``, quadratic
(0.1M frames 18 s, 0.4M 97 s of clustering on Bandai-Namco copies)."""

CELL_CLUSTERS = 256
"""Clusters per first-stage cell of :func:`two_stage_kmeans`."""


def two_stage_kmeans(
    emb: npt.NDArray[np.float32],
    k: int,
    blocks_per_cluster: int,
    seed: int = 0,
    cell_clusters: int = CELL_CLUSTERS,
) -> npt.NDArray[np.int32]:
    """``(N,)`` cluster ids ``0..K-1`` (``K`` about ``k``) of blocks ``emb (N, D)``: k-means into
    ``ceil(k / cell_clusters)`` cells, then each cell's blocks into ``n_cell / blocks_per_cluster``
    clusters, so every cluster still holds about ``blocks_per_cluster`` similar blocks while the
    work is ``O(N * cell_clusters)`` (plus ``O(N * k / cell_clusters)`` for the cells), not
    ``O(N * k)``. Ids are dense (every id has members)."""
    if emb.shape[0] == 0:
        raise ValueError("no blocks to cluster")
    cells = -(-k // cell_clusters)
    km = MiniBatchKMeans(n_clusters=cells, random_state=seed, n_init=3, batch_size=4096, max_iter=50)
    cell = km.fit_predict(emb)
    out = np.empty(emb.shape[0], dtype=np.int64)
    next_id = 0
    for c in range(cells):
        idx = np.flatnonzero(cell == c)
        kc = max(1, min(idx.size, int(round(idx.size / blocks_per_cluster))))
        if idx.size == 0:
            continue
        if kc == 1:
            out[idx] = next_id
        else:
            sub = MiniBatchKMeans(n_clusters=kc, random_state=seed, n_init=3, batch_size=4096, max_iter=50)
            out[idx] = next_id + sub.fit_predict(emb[idx])
        next_id += kc
    _, dense = np.unique(out, return_inverse=True)
    return np.asarray(dense, dtype=np.int32).reshape(-1)


def cluster_blocks(
    features: npt.NDArray[np.float32],
    labels: npt.NDArray[np.int8],
    counts: Sequence[int],
    sizes: Sequence[int],
    coarse_clusters: int,
    blocks_per_cluster: int,
    label_weight: float = 1.0,
    seed: int = 0,
    progress: Callable[[float, str], None] | None = None,
    max_flat: int = MAX_FLAT_CLUSTERS,
) -> dict[int, npt.NDArray[np.int32]]:
    """Per block size, ``(F,)`` int32 the cluster of the block starting at each database frame
    (-1 where no block of that size fits). A finer level of more than ``max_flat`` clusters is
    clustered in two stages (:func:`two_stage_kmeans`), linear in the blocks."""
    total = int(sum(counts))
    out: dict[int, npt.NDArray[np.int32]] = {}
    for level, size in enumerate(sizes):
        starts = block_starts(counts, size)
        cl = np.full(total, -1, dtype=np.int32)
        if starts.size:
            k = coarse_clusters if level == 0 else int(round(starts.size / blocks_per_cluster))
            k = max(1, min(k, starts.size))
            emb = block_embedding(features, labels, starts, size, label_weight)
            if k == 1:
                cl[starts] = 0
            elif level > 0 and k > max_flat:
                cl[starts] = two_stage_kmeans(emb, k, blocks_per_cluster, seed)
            else:
                km = MiniBatchKMeans(n_clusters=k, random_state=seed, n_init=3, batch_size=4096, max_iter=50)
                cl[starts] = km.fit_predict(emb).astype(np.int32)
        out[size] = cl
        if progress is not None:
            progress((level + 1) / len(sizes), f"{starts.size} blocks of {size} frames clustered")
    return out
