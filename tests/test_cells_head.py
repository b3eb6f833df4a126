"""LandNet-E's second cell head (landfall_train.cells_head): grafted beside the first as the model's rank
cells, the first head's cells and clear site stay as they were to the bit, and both runtimes read the
graph; the kinds of place render labelled patches (standing crops labelled apart)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from companion.reasoning.landnet import PACKAGED, RANK_CELLS, LandNet
from landfall_train.labels import CLASSES, CLASSES_WITH_CROP, CROP, label_map
from simbridge.world.model import SurfaceClass as C
from simbridge.world.raycast import HIT_TOP

onnx = pytest.importorskip("onnx", reason="the second cell head needs onnx: pip install -e '.[train]'")
ort = pytest.importorskip("onnxruntime")

E = PACKAGED["landnet-e"]


def test_a_graft_of_the_first_heads_weights_reads_as_the_first_head_and_leaves_it_be(tmp_path: Path) -> None:
    from landfall_train.cells_head import check_unchanged, first_head, graft, unhalved, without_rank_cells

    out = tmp_path / "grafted.onnx"
    base = without_rank_cells(unhalved(E))  # the packaged model's own second head taken out first
    assert RANK_CELLS not in [o.name for o in base.graph.output]
    onnx.save(graft(base, first_head(base), len(CLASSES)), str(out))
    assert check_unchanged(E, out) == 0.0  # the first head's cells and the clear site, to the bit
    x = np.random.default_rng(3).normal(0.0, 1.0, (2, 3, 96, 144)).astype(np.float32)
    session = ort.InferenceSession(str(out), providers=["CPUExecutionProvider"])
    cells, rank_cells = session.run(["cells", RANK_CELLS], {"image": x})
    assert rank_cells.shape == cells.shape == (2, len(CLASSES), 12, 18)
    np.testing.assert_allclose(rank_cells, cells, atol=1e-5)  # the same weights, a second copy
    import cv2

    net = cv2.dnn.readNetFromONNX(str(out))  # the companion's second runtime reads the graft too
    net.setInput(x[:1])
    cv_cells, cv_rank = net.forward(["cells", RANK_CELLS])
    np.testing.assert_allclose(cv_cells, cells[:1], atol=1e-3)
    np.testing.assert_allclose(cv_rank, rank_cells[:1], atol=1e-3)


def test_unhalving_and_halving_again_gives_the_packaged_weights_back(tmp_path: Path) -> None:
    from landfall_train.cells_head import unhalved
    from landfall_train.package import halve

    full = tmp_path / "full.onnx"
    onnx.save(unhalved(E), str(full))
    assert full.stat().st_size > 1.8 * E.stat().st_size
    halve(full, tmp_path / "half.onnx")
    a, b = onnx.load(str(E)), onnx.load(str(tmp_path / "half.onnx"))
    assert {i.name: i.raw_data for i in a.graph.initializer} == {
        i.name: i.raw_data for i in b.graph.initializer
    }


def test_crops_are_their_own_class_only_when_asked() -> None:
    hit_class = np.array([[int(C.CROP), int(C.GRASS)]], np.uint8)
    kind = np.full(hit_class.shape, HIT_TOP, np.uint8)
    material = np.zeros_like(hit_class)
    veg = CLASSES.index("low_vegetation")
    assert label_map(hit_class, material, kind).tolist() == [[veg, veg]]
    assert label_map(hit_class, material, kind, crops=True).tolist() == [[CROP, veg]]
    assert CLASSES_WITH_CROP[CROP] == "crop"


def test_a_model_with_rank_cells_reads_ranks_and_the_search_with_them_and_confirmations_without() -> None:
    """The packaged LandNet-E carries the second head: a rank's reading and the search's presence come
    from it, a confirmation's from the first head."""
    net = LandNet.load(E)
    assert net.rank_cell_thresholds is not net.cell_thresholds
    rgb = np.random.default_rng(4).integers(0, 256, (96, 128, 3), dtype=np.uint8)
    first = net.probabilities(rgb)
    rank = net._infer(rgb, 1, None, rank=True)[0][0]
    assert first.shape == rank.shape
    assert not np.allclose(first, rank)
    assert (net.presence(rgb) == (rank >= net.rank_cell_thresholds[:, None, None])).all()


def test_a_kind_of_place_renders_labelled_patches_with_its_crops_and_keeps_evaluation_seeds_out() -> None:
    from landfall_train.patches import PATCH_PX, PLACE_GSD_M, render_place

    rgb, labels, meta = render_place("farmland", 100, 12, 0)
    assert rgb.shape == (12, PATCH_PX, PATCH_PX, 3)
    assert labels.shape == (12, PATCH_PX, PATCH_PX)
    assert (labels == CROP).any()  # farmland's fields of standing crops, labelled as such
    assert all(PLACE_GSD_M[0] <= m["gsd_m"] <= PLACE_GSD_M[1] for m in meta)
    again = render_place("farmland", 100, 12, 0)
    assert (again[0] == rgb).all()  # the same seed, the same bytes
    with pytest.raises(ValueError, match="reserved for evaluation"):
        render_place("farmland", 3, 1, 0)
