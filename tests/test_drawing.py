"""iloci.drawing's library pieces that need no simulator: images, concept names, errors."""

from __future__ import annotations

import numpy as np
import pytest

from iloci.errors import InvalidInputError, MissingBackendError, UnknownComponentError


def test_write_png_round_trips_the_pixels(tmp_path):
    Image = pytest.importorskip("PIL.Image")
    from iloci.drawing import write_png

    img = np.random.default_rng(0).integers(0, 256, (7, 11, 3), dtype=np.uint8)
    out = write_png(tmp_path / "sub" / "a.png", img)
    with Image.open(out) as back:
        assert back.format == "PNG" and back.mode == "RGB"
        assert np.array_equal(np.asarray(back), img)
    with pytest.raises(InvalidInputError, match=r"\(H, W, 3\)"):
        write_png(tmp_path / "b.png", img[..., 0])
    assert not (tmp_path / "b.png").exists()


def test_write_gif_holds_every_frame(tmp_path):
    Image = pytest.importorskip("PIL.Image")
    from iloci.drawing import write_gif

    frames = [np.full((8, 8, 3), v, np.uint8) for v in (0, 120, 255)]
    out = write_gif(tmp_path / "a.gif", frames, 0.05)
    with Image.open(out) as back:
        assert back.n_frames == 3


def test_resolve_concept_by_robot_label_or_true_concept():
    from iloci.concepts.memory import Entry, Memory
    from iloci.drawing import resolve_concept

    def entry(concept, source):
        return Entry(pb=np.zeros(4), pb_rec=np.zeros(4), num_samples=1, num_steps=3,
                     initial_input=np.zeros(6), start=np.zeros(6), dt=0.1, concept=concept,
                     generation_error=0.0, source=source, sources=(source,))

    mem = Memory()
    mem.entries = [entry("c1", "GShape/0"), entry("c2", "Leaf_1/0"), entry("c2", "Leaf_2/1")]
    assert resolve_concept(mem, "c2") == "c2"
    assert resolve_concept(mem, "Leaf") == "c2"  # the true concept of both leaves
    with pytest.raises(InvalidInputError, match="Did you mean 'GShape'"):
        resolve_concept(mem, "Gshape")
    with pytest.raises(InvalidInputError, match="teach the robot first"):
        resolve_concept(Memory(), "c1")


@pytest.mark.parametrize("exc", [
    MissingBackendError("IK solver", "pinocchio", ["pinocchio"], "pip install x"),
    UnknownComponentError("IK solver", "nope", ["pinocchio"]),
])
def test_with_context_keeps_type_and_attributes(exc):
    out = exc.with_context("memory.npz needs it: ")
    assert type(out) is type(exc) and out is not exc
    assert str(out) == "memory.npz needs it: " + str(exc)
    assert out.name == exc.name and out.kind == exc.kind
    assert str(exc).startswith("memory.npz") is False  # the original is untouched
