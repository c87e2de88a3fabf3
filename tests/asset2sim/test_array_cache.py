"""The on-disk array cache proves its entries (asset2sim.array_cache): an
entry copied to another key, a NaN-filled entry and a zip bomb are rejected
with a CacheWarning, computed again and rewritten; the cache never lives
inside a refine's input or output folder."""

from __future__ import annotations

import io
import json
import shutil
import tracemalloc
import warnings
import zipfile
from pathlib import Path

import numpy as np
import pytest

from asset2sim import array_cache, urdf
from asset2sim.array_cache import CacheWarning
from asset2sim.schemas.asset import LinkGeometry
from asset2sim.tasks.geometry import analyze as an
from asset2sim.tasks.assemble import collision_geometry as cg
from tests.tasks.geometry.test_analyze import box_mesh, link_of, mesh_ref, write_obj
from tests.tasks.state.test_clearance import write_stacked_drawers
from tests.helpers import tree_hashes


@pytest.fixture
def cache(tmp_path, monkeypatch) -> Path:
    root = tmp_path / "cache"
    monkeypatch.setenv("ASSET2SIM_CACHE", str(root))
    return root


def _fresh_pieces() -> None:
    """Forget the pieces kept in this process (a new process, as far as the disk cache goes)."""
    cg._PIECE_CACHE.clear()
    cg._STATE_CACHE.clear()


def test_proven_entry_round_trips_and_store_refuses_the_reserved_name(cache):
    arrays = {"x": np.arange(6.0).reshape(2, 3), "n": np.array(3), "t": array_cache.text_array("{}")}
    array_cache.store("k", "a" * 64, arrays)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        back = array_cache.load("k", "a" * 64)
    assert set(back) == set(arrays)
    assert all(np.array_equal(back[k], arrays[k]) and back[k].dtype == arrays[k].dtype for k in arrays)
    assert array_cache.load("other-kind", "a" * 64) is None  # no file there: a plain miss
    with pytest.raises(ValueError, match="reserved"):
        array_cache.store("k", "b" * 64, {"__cache__": np.zeros(1)})


def test_entry_moved_to_another_key_is_rejected_recomputed_and_rewritten(cache, tmp_path, monkeypatch):
    """The 'huge' run's analysis copied over a normal-size link's entry (as when
    ``analysis/`` entries are rotated) is not read back as that link's."""
    v, f = box_mesh(1.0, 1.0, 1.0)
    small = link_of([mesh_ref(write_obj(tmp_path / "small.obj", v * 0.1, f))])
    huge = link_of([mesh_ref(write_obj(tmp_path / "huge.obj", v * 10.0, f))])
    g_small = an.analyze_link(small)
    [small_entry] = (cache / an.DISK_KIND).glob("*.npz")
    g_huge = an.analyze_link(huge)
    [huge_entry] = set((cache / an.DISK_KIND).glob("*.npz")) - {small_entry}
    assert g_huge.volume == pytest.approx(1e6 * g_small.volume, rel=1e-9)
    shutil.copyfile(huge_entry, small_entry)

    calls = []
    real = an._analyze_surface
    monkeypatch.setattr(an, "_analyze_surface", lambda *a: calls.append(1) or real(*a))
    with pytest.warns(CacheWarning, match="moved between keys"):
        again = an.analyze_link(small)
    assert calls == [1] and again == g_small  # computed again, not the huge link's
    # rewritten under its own key: read back (no warning, no computation)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        entry = array_cache.load(an.DISK_KIND, small_entry.stem)
        assert an.analyze_link(small) == g_small and calls == [1]
    assert LinkGeometry.model_validate_json(array_cache.array_text(entry["json"])) == g_small


def test_altered_entry_is_rejected(cache):
    array_cache.store("k", "c" * 64, {"x": np.ones(4)})
    path = cache / "k" / f"{'c' * 64}.npz"
    with np.load(path) as npz:
        arrays = {k: npz[k] for k in npz.files}
    arrays["x"] = arrays["x"] * 11.0  # the arrays altered, the proof kept
    np.savez(path, **arrays)
    with pytest.warns(CacheWarning, match="do not match their digest"):
        assert array_cache.load("k", "c" * 64) is None
    assert not path.exists()
    path.parent.mkdir(exist_ok=True)
    np.savez(path, x=np.ones(4))  # an entry without a proof (an older version's)
    with pytest.warns(CacheWarning, match="no proof"):
        assert array_cache.load("k", "c" * 64) is None


def test_nan_filled_pieces_entry_is_rejected_recomputed_and_rewritten(cache, tmp_path):
    """A ``pieces/`` entry whose numbers are NaN (its proof made to match, so
    only the finiteness check can catch it) is not handed to the writer."""
    folder = write_stacked_drawers(tmp_path / "a").parent

    def pieces_of():
        return cg.link_pieces(urdf.read_urdf(folder / "mobility.urdf"), lambda g: folder / str(g.filename))

    _fresh_pieces()
    computed, notes = pieces_of()
    [entry] = (cache / "pieces").glob("*.npz")
    with np.load(entry) as npz:
        arrays = {k: npz[k] for k in npz.files}
    proof = json.loads(array_cache.array_text(arrays.pop("__cache__")))
    bad = {k: np.full_like(a, np.nan) if a.dtype.kind == "f" else a for k, a in arrays.items()}
    proof["sha256"] = array_cache.content_digest(bad)
    np.savez(entry, **bad, __cache__=array_cache.text_array(json.dumps(proof)))

    _fresh_pieces()
    with pytest.warns(CacheWarning, match="NaN"):
        again, notes2 = pieces_of()
    assert notes2 == notes
    for name in computed:
        for a, b in zip(computed[name], again[name], strict=True):
            assert np.array_equal(a.points, b.points) and np.array_equal(a.equations, b.equations) and a.volume == b.volume
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rewritten = array_cache.load("pieces", entry.stem)
    assert rewritten is not None and all(np.isfinite(a).all() for a in rewritten.values() if a.dtype.kind == "f")


def test_store_writes_no_entry_load_would_reject(cache):
    array_cache.store("k", "d" * 64, {"x": np.array([1.0, np.inf])})
    assert not (cache / "k").exists()


def _npy_header(shape: tuple[int, ...]) -> bytes:
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(buf, {"descr": "<f8", "fortran_order": False, "shape": shape})
    return buf.getvalue()


def test_zip_bomb_entry_is_rejected_without_inflating_it(cache):
    """A small deflated entry that inflates to twice the cap is refused from
    its zip directory: nothing near its size is ever allocated."""
    key = "e" * 64
    path = cache / "pieces" / f"{key}.npz"
    path.parent.mkdir(parents=True)
    n = 2 * array_cache.MAX_ENTRY_BYTES // 8
    chunk = bytes(1 << 20)
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf, zf.open("p0.npy", "w", force_zip64=True) as fh:
        fh.write(_npy_header((n,)))
        for _ in range(n * 8 // len(chunk)):
            fh.write(chunk)
    assert path.stat().st_size < (1 << 20) < array_cache.MAX_ENTRY_BYTES
    tracemalloc.start()
    try:
        with pytest.warns(CacheWarning, match="uncompressed, more than"):
            assert array_cache.load("pieces", key) is None
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 8 << 20
    assert not path.exists()  # deleted: the caller's store writes a proven entry there

    # a member whose .npy header declares far more than the member holds
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("p0.npy", _npy_header((10**12,)) + bytes(64))
    with pytest.warns(CacheWarning, match="header declares an array larger"):
        assert array_cache.load("pieces", key) is None


def test_guard_refuses_a_cache_inside_a_kept_out_folder_through_symlinks(tmp_path, monkeypatch):
    inside = tmp_path / "input" / "cache"
    (tmp_path / "input").mkdir()
    (tmp_path / "link").symlink_to(tmp_path / "input")
    monkeypatch.setenv("ASSET2SIM_CACHE", str(tmp_path / "link" / "cache"))  # the input, through a symlink
    assert array_cache.cache_dir() == tmp_path / "link" / "cache"
    with array_cache.guard(tmp_path / "input", None):
        with pytest.warns(CacheWarning, match="inside"):
            assert array_cache.cache_dir() is None
        array_cache.store("k", "f" * 64, {"x": np.ones(2)})
        assert array_cache.load("k", "f" * 64) is None
    assert not inside.exists()
    assert array_cache.cache_dir() == tmp_path / "link" / "cache"  # the guard ended with the block
    with array_cache.guard(tmp_path / "elsewhere"):
        assert array_cache.cache_dir() == tmp_path / "link" / "cache"


def test_refine_with_the_cache_inside_the_input_or_output_writes_nothing_there(demo_root, tmp_path, monkeypatch):
    """ASSET2SIM_CACHE inside the input folder (which once wrote eight .npz
    files into the input) or the output folder: the refine warns, runs
    without the disk cache and leaves the input byte-for-byte as it was."""
    from asset2sim.tasks.refine import refine_asset

    prompt = "A small box with its lid slightly open."
    src = tmp_path / "in"
    shutil.copytree(demo_root / "box_lid", src)
    # the control: the same refine with the cache outside both writes entries
    monkeypatch.setenv("ASSET2SIM_CACHE", str(tmp_path / "cache"))
    _fresh_pieces()
    refine_asset(src, prompt, tmp_path / "out0", extras=False)
    assert list((tmp_path / "cache").rglob("*.npz"))

    before = tree_hashes(src)
    monkeypatch.setenv("ASSET2SIM_CACHE", str(src / "cache"))
    _fresh_pieces()
    with pytest.warns(CacheWarning, match="inside"):
        refine_asset(src, prompt, tmp_path / "out1", extras=False)
    assert tree_hashes(src) == before and not (src / "cache").exists()

    out = tmp_path / "out2"
    monkeypatch.setenv("ASSET2SIM_CACHE", str(out / "cache"))
    _fresh_pieces()
    with pytest.warns(CacheWarning, match="inside"):
        refine_asset(src, prompt, out, extras=False)
    assert not (out / "cache").exists() and not list(out.rglob("*.npz"))
    assert tree_hashes(src) == before
