"""Label propagation: exclusive label sets, per-clip Viterbi decoding, self-training and the
multi-scale embedding window, on small synthetic inputs whose answers are known."""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np
import pytest

from engines.annotations.features import embedding_offsets, window_offsets
from engines.annotations.propagate import (
    SvmEmbedding,
    change_windows,
    decode,
    known_labels,
    label_states,
    propagate,
    pseudo_labels,
    refine_changes,
    viterbi,
)


def _full(label: str, n: int) -> dict[str, Any]:
    return {"label": label, "start": 0, "end": n, "value": 1}


def test_states_are_cliques_of_cooccurring_labels() -> None:
    labels = [[_full("walk", 4), _full("wave", 4)], [_full("run", 4)], [_full("walk", 4)]]
    vocab = ["walk", "wave", "run"]
    values, known = known_labels(labels, [4, 4, 4], vocab)
    states = label_states(values, known)
    assert states is not None
    got = [tuple(vocab[j] for j in np.flatnonzero(s > 0)) for s in states]
    # walk + wave co-occur; run never appears with either, so no run + walk / run + wave; the
    # empty state (no label) is always there, last
    assert set(got) == {("walk",), ("wave",), ("run",), ("walk", "wave"), ()} and len(got) == 5
    assert got[-1] == ()


def test_a_frame_no_svm_claims_stays_unlabelled() -> None:
    labels = [[_full("walk", 3)], [_full("run", 3)], []]
    vocab = ["walk", "run"]
    values, known = known_labels(labels, [3, 3, 3], vocab)
    states = label_states(values, known)
    assert states is not None
    d = np.where(known, values, 0.0).astype(np.float64)
    d[6:] = [[-0.3, -0.8]] * 3  # a kick among walks and runs: both SVMs say no
    out, _ = decode(d, values, known, [3, 3, 3], states, 0.0)
    assert (out[6:] == -1).all()


def test_too_many_states_falls_back_to_independent_labels() -> None:
    n = 12
    values = np.ones((1, n), dtype=np.int8)  # every label co-occurs with every other: 2^12 - 1 cliques
    known = np.ones((1, n), dtype=bool)
    assert label_states(values, known, max_states=100) is None


def test_viterbi_switch_cost_removes_flicker_but_keeps_real_changes() -> None:
    score = np.zeros((40, 2))
    score[:20, 0] = 1.0
    score[20:, 1] = 1.0
    score[8:10] = [[0.0, 1.0]] * 2  # a 2-frame blip of state 1 inside state 0
    free = viterbi(score, [40], 0.0)
    assert free[8:10].tolist() == [1, 1]
    sticky = viterbi(score, [40], 5.0)
    assert sticky[:20].tolist() == [0] * 20 and sticky[20:].tolist() == [1] * 20
    # a change is never carried across clips
    two = viterbi(score, [20, 20], 50.0)
    assert two[0] == 0 and two[-1] == 1


def test_viterbi_batches_match_one_by_one() -> None:
    rng = np.random.default_rng(0)
    counts = [5, 17, 1, 9, 30, 2]
    score = rng.normal(size=(sum(counts), 3))
    together = viterbi(score, counts, 1.5, batch=4)
    offsets = np.concatenate(([0], np.cumsum(counts)))
    alone = np.concatenate([viterbi(score[a:b], [b - a], 1.5) for a, b in itertools.pairwise(offsets)])
    np.testing.assert_array_equal(together, alone)


def test_decode_exclusive_picks_the_best_allowed_set() -> None:
    vocab = ["walk", "wave", "run"]
    values, known = known_labels(
        [[_full("walk", 1), _full("wave", 1)], [_full("run", 1)], [], [], []], [1, 1, 1, 1, 1], vocab
    )
    states = label_states(values, known)
    d = np.array(
        [
            [1.0, 1.0, -1.0],
            [-1.0, -1.0, 1.0],
            [-0.2, -0.9, -0.5],  # every SVM says no: no label
            [0.8, -0.4, 0.6],  # walk and run both positive, but they exclude each other
            [0.5, 0.7, -1.0],  # walk + wave together
        ]
    )
    labels, conf = decode(d, values, known, [1] * 5, states, 0.0)
    rows = [tuple(vocab[j] for j in np.flatnonzero(r > 0)) for r in labels]
    assert rows == [("walk", "wave"), ("run",), (), ("walk",), ("walk", "wave")]
    assert np.all(conf > 0)
    np.testing.assert_allclose(conf[:2], 1.0)  # user-given
    # independent decoding is the sign of each SVM
    plain, plain_conf = decode(d, values, known, [1] * 5, None, 0.0)
    assert plain[2].tolist() == [-1, -1, -1] and plain[3].tolist() == [1, -1, 1]
    np.testing.assert_allclose(plain_conf[2:], np.maximum(np.abs(d[2:]), 0.05))


def test_decode_respects_user_values_within_a_clip() -> None:
    vocab = ["a", "b"]
    labels = [[_full("a", 2)], [_full("b", 2)], [{"label": "a", "start": 0, "end": 3, "value": 1}]]
    values, known = known_labels(labels, [2, 2, 6], vocab)
    states = label_states(values, known)
    d = np.where(known, values, 0.0).astype(np.float64)
    d[4:] = [[-1.0, 1.0]] * 6  # the SVMs say "b" throughout the third clip
    labels_out, _ = decode(d, values, known, [2, 2, 6], states, 100.0)
    assert labels_out[4:7, 0].tolist() == [1, 1, 1]  # the user's "a" stands
    assert labels_out[4:, 0].sum() + labels_out[4:, 1].sum() == 0  # one label per frame


def test_pseudo_labels_take_the_confident_share_of_each_combination() -> None:
    labels = np.array([[1, -1]] * 6 + [[-1, 1]] * 4, dtype=np.int8)
    conf = np.array([[0.1], [0.9], [0.5], [0.7], [0.3], [2.0], [0.2], [0.8], [0.4], [0.6]]).repeat(2, axis=1)
    known = np.zeros_like(labels, dtype=bool)
    known[5] = True  # user-given frames are never pseudo-labelled
    chosen = pseudo_labels(labels, conf, known, 0.5)
    assert np.flatnonzero(chosen).tolist() == [1, 3, 7, 9]  # 5 free frames -> 2, 4 -> 2
    assert not pseudo_labels(labels, conf, known, 0.0).any()


def _blobs(rng: np.random.Generator, centre: tuple[float, float], n: int) -> np.ndarray:
    return np.asarray(centre) + 0.3 * rng.normal(size=(n, 2))


def test_propagate_exclusive_and_self_training() -> None:
    """Three well-separated kinds of clip, one labelled each; one kind carries two labels."""
    rng = np.random.default_rng(1)
    kinds = {"A": (0.0, 0.0), "B": (3.0, 0.0), "C": (0.0, 3.0)}
    n = 20
    emb, labels, truth = [], [], []
    for kind, centre in kinds.items():
        for i in range(4):
            emb.append(_blobs(rng, centre, n))
            truth.append(kind)
            if i == 0:
                labs = [_full("walk", n), _full("wave", n)] if kind == "C" else [_full(kind, n)]
                labels.append(labs)
            else:
                labels.append([])
    x = np.concatenate(emb)
    counts = [n] * len(truth)
    clip_of = np.repeat(np.arange(len(truth)), counts)
    for self_training in (0, 1):
        prop = propagate(
            x, clip_of, counts, labels, gammas=[1.0], switch_cost=5.0, self_training=self_training
        )
        assert prop.vocab == ["A", "B", "walk", "wave"]
        want = {"A": [1, -1, -1, -1], "B": [-1, 1, -1, -1], "C": [-1, -1, 1, 1]}
        expected = np.array([want[t] for t in truth for _ in range(n)])
        assert np.mean(np.all(prop.labels == expected, axis=1)) > 0.97
        # the stored confidence has the labels' signs
        assert np.all(np.sign(prop.decision) == prop.labels)
        if self_training:
            assert all(m.train_frames > 3 * n for m in prop.models)  # 3n annotated


def test_embedding_offsets_add_a_coarse_context() -> None:
    fine = window_offsets(30.0, 1.0, 7)
    assert embedding_offsets(30.0, 1.0, 7).tolist() == fine.tolist()
    assert embedding_offsets(30.0, 1.0, 7, 0.0, 9).tolist() == fine.tolist()
    both = embedding_offsets(30.0, 1.0, 7, 4.0, 9)
    assert both.tolist() == sorted(set(fine.tolist()) | set(range(-60, 61, 15)))


def _two_state_score(n: int, change: int) -> np.ndarray:
    """``(n, 2)`` scores preferring state 0 before ``change`` and state 1 from it on."""
    score = np.zeros((n, 2))
    score[:change, 0], score[change:, 1] = 1.0, 1.0
    return score


def test_refine_changes_moves_a_blurred_change_to_the_sharp_evidence() -> None:
    n, reach = 100, 10
    pick = np.array([0] * 56 + [1] * 44)  # the context-window decoding put the change at 56
    fine = _two_state_score(n, 50)  # the fine window says 50
    assert refine_changes(pick, fine, [n], reach).tolist() == [0] * 50 + [1] * 50
    # never farther than reach: the sharp evidence 12 frames away only pulls the change 10
    far = refine_changes(np.array([0] * 62 + [1] * 38), fine, [n], reach)
    assert np.flatnonzero(np.diff(far)).tolist() == [51]
    # reach 0 leaves the decoding alone; changes are never carried across clips
    np.testing.assert_array_equal(refine_changes(pick, fine, [n], 0), pick)
    np.testing.assert_array_equal(refine_changes(pick, fine, [56, 44], reach), pick)


def test_refine_changes_absorbs_short_blur_runs_between_two_states() -> None:
    n, reach = 100, 10
    # state 0, then 6 frames of the empty state 2 where the context straddles the change, then 1
    pick = np.array([0] * 47 + [2] * 6 + [1] * 47)
    fine = np.zeros((n, 3))
    fine[:, :2] = _two_state_score(n, 50)
    assert refine_changes(pick, fine, [n], reach).tolist() == [0] * 50 + [1] * 50
    # a run of reach frames or more is an action of its own: only its two changes move
    long_run = np.array([0] * 40 + [2] * 20 + [1] * 40)
    out = refine_changes(long_run, fine, [n], reach, min_run=reach)
    assert set(out[40:60].tolist()) >= {2}
    # min_run 1 keeps every run: the short run shrinks to one frame but stays
    kept = refine_changes(pick, fine, [n], reach, min_run=1)
    assert (kept == 2).sum() >= 1 and kept[0] == 0 and kept[-1] == 1


def test_refine_changes_needs_fine_svms_that_agree_beyond_the_blur() -> None:
    n, reach = 100, 10
    pick = np.array([0] * 56 + [1] * 44)
    fine = _two_state_score(n, 50)
    fine[30:47] = [0.0, 1.0]  # 10-20 frames before the change the fine SVMs prefer the other state
    np.testing.assert_array_equal(refine_changes(pick, fine, [n], reach), pick)
    assert refine_changes(pick, fine, [n], reach, agree=0.0).tolist() == [0] * 50 + [1] * 50


def test_refine_changes_rejects_bad_input() -> None:
    pick = np.zeros(10, dtype=np.intp)
    with pytest.raises(ValueError, match="reach"):
        refine_changes(pick, np.zeros((10, 2)), [10], -1)
    with pytest.raises(ValueError, match="agree"):
        refine_changes(pick, np.zeros((10, 2)), [10], 3, agree=1.5)
    with pytest.raises(ValueError, match="fine_score"):
        refine_changes(pick, np.zeros((9, 2)), [10], 3)
    with pytest.raises(ValueError, match="frames"):
        SvmEmbedding(np.zeros((10, 3)), np.zeros((9, 2)), 3)


def test_change_windows_cover_twice_the_reach_within_clips() -> None:
    pick = np.array([0] * 20 + [1] * 20 + [1] * 20)
    near = change_windows(pick, [40, 20], 3)
    assert np.flatnonzero(near).tolist() == list(range(14, 26))  # the clip boundary at 40 is no change
    assert not change_windows(pick, [40, 20], 0).any()


def test_propagate_refines_changes_with_the_fine_embedding() -> None:
    """A combined embedding whose context straddles a change matches neither action (as a 4 s
    window half walk, half wave does), and a sharp fine one: the fine SVMs put the change back
    where it is and the frames between get a label again."""
    rng = np.random.default_rng(2)
    n, blur = 60, 12
    centre = {"A": np.array([0.0, 0.0]), "B": np.array([3.0, 0.0])}

    def clip(parts: list[tuple[str, int]]) -> tuple[np.ndarray, np.ndarray]:
        fine = np.concatenate([centre[k] + 0.2 * rng.normal(size=(m, 2)) for k, m in parts])
        # the context: mean and spread over 2 * blur + 1 frames (the spread is large only where
        # the window straddles a change, unlike any labelled frame)
        pad = np.pad(fine, [(blur, blur), (0, 0)], mode="edge")
        win = np.stack([pad[i : i + 2 * blur + 1] for i in range(fine.shape[0])])
        return np.hstack((fine, 3.0 * win.mean(axis=1), 9.0 * win.std(axis=1))), fine

    clips = [clip([("A", n)]), clip([("B", n)]), clip([("A", n)]), clip([("B", n)])]
    joined = [clip([("A", 40), ("B", 40)]) for _ in range(3)]
    combined = np.concatenate([c for c, _ in clips + joined])
    fine = np.concatenate([f for _, f in clips + joined])
    counts = [n] * 4 + [80] * 3
    clip_of = np.repeat(np.arange(len(counts)), counts)
    labels: list[list[dict[str, Any]]] = [[_full("A", n)], [_full("B", n)], [_full("A", n)], [_full("B", n)]]
    labels += [[] for _ in joined]
    kw: dict[str, Any] = {"gammas": [1.0], "switch_cost": 5.0, "self_training": 0}
    plain = propagate(combined, clip_of, counts, labels, **kw)
    sharp = propagate(SvmEmbedding(combined, fine, blur), clip_of, counts, labels, **kw)
    want = np.concatenate([np.tile([[1, -1]], (40, 1)), np.tile([[-1, 1]], (40, 1))] * 3)
    wrong = {
        name: int(np.sum(np.any(p.labels[4 * n :] != want, axis=1)))
        for name, p in (("plain", plain), ("sharp", sharp))
    }
    assert wrong["plain"] >= 6 and wrong["sharp"] <= 2, wrong
    assert np.all(np.sign(sharp.decision) == sharp.labels)
    # without a fine part (or with reach 0) nothing changes
    same = propagate(SvmEmbedding(combined, None, blur), clip_of, counts, labels, **kw)
    np.testing.assert_array_equal(same.labels, plain.labels)
