"""The convex decomposition's process cache: a decomposition asked for again in a process is not computed again,
with the on-disk cache off, and what it hands out is the same as a fresh CoACD run's."""

import numpy as np
import pytest

coacd = pytest.importorskip("coacd")

from asset2sim.tasks.geometry import decomposition  # noqa: E402
from tests.conftest import NO_SHARED, SHARED as DEV  # noqa: E402

#: The stapler's base (PartNet-Mobility 102990): the mesh its collision repair decomposes (5 pieces).
BASE_MESH = DEV / "102990" / "textured_objs" / "original-6.obj"


@pytest.fixture
def counted(monkeypatch):
    """The on-disk cache off, the process cache empty, and the list of CoACD calls made."""
    if not BASE_MESH.is_file():
        pytest.skip(NO_SHARED)
    monkeypatch.setenv("ASSET2SIM_CACHE", "off")
    monkeypatch.setattr(decomposition, "_MEMO", type(decomposition._MEMO)(maxsize=decomposition._MEMO.maxsize))
    calls = []
    run = coacd.run_coacd

    def counting(mesh, **kwargs):
        calls.append(kwargs)
        return run(mesh, **kwargs)

    monkeypatch.setattr(coacd, "run_coacd", counting)
    return calls


def _same(a, b) -> bool:
    return len(a) == len(b) and all(np.array_equal(va, vb) and np.array_equal(fa, fb) for (va, fa), (vb, fb) in zip(a, b))


def test_a_decomposition_asked_for_twice_runs_coacd_once_and_gives_the_same_pieces(counted):
    first = decomposition.decompose_mesh(BASE_MESH)
    again = decomposition.decompose_mesh(BASE_MESH)
    assert len(counted) == 1  # with the disk cache off, the second call used to run CoACD again
    assert len(first) >= 2 and _same(first, again)
    # what the process cache answered is what CoACD makes without it
    decomposition._MEMO.clear()
    fresh = decomposition.decompose_mesh(BASE_MESH)
    assert len(counted) == 2 and _same(fresh, again)


def test_the_pieces_handed_out_are_copies_a_caller_may_change(counted):
    first = decomposition.decompose_mesh(BASE_MESH)
    kept = [(v.copy(), f.copy()) for v, f in first]
    first[0][0][:] = 0.0  # a caller moving its pieces in place
    first[0][1][:] = 0
    again = decomposition.decompose_mesh(BASE_MESH)
    assert _same(again, kept) and again[0][0].flags.writeable
    assert len(counted) == 1


@pytest.mark.slow  # end to end: a second whole CoACD decomposition (the first stays in the fast tier)
def test_other_settings_are_another_decomposition(counted):
    mesh = decomposition.read_mesh(BASE_MESH)
    v, f = mesh.vertices, mesh.faces
    coarse = {**decomposition.COACD_SETTINGS, "max_convex_hull": 2}
    a = decomposition.decompose(v, f, coarse, refit=False)
    b = decomposition.decompose(v, f, coarse, refit=True)
    assert len(counted) == 2  # the refit is part of the key: not answered from the first
    assert len(a) <= 2 and len(b) == len(a)
    assert decomposition.decompose(v, f, coarse, refit=True) is not b and len(counted) == 2
