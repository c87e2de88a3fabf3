"""The malformed corpus: every generated broken asset gets its expected code,
fast, without crash or hang, and extraction (hence ``refine``) refuses it."""

from __future__ import annotations

import collections
import re

import pytest

from asset2sim import cli
from asset2sim.tasks.ingest import validate_input as vi
from asset2sim.tasks.ingest.extract import AssetError, extract_asset_checked
from tests import corpus_builder as cb
from tests.conftest import ROOT
from tests.helpers import tree_hashes, no_hang

#: A case's validation that runs longer than this is stopped as hung (a guard against a loop or a bomb read in full,
#: not a speed goal: ``benchmarks/`` measures speed).
HANG_LIMIT_S = 30


#: Cases whose files are 1-2 GB (sparse) to write and read: the end-to-end tier.
HUGE = {"files_meta_1gb_sparse", "texture_2gb_sparse"}


def _tiered(cases) -> list:
    """``cases`` as parameters named by the case, the ``HUGE`` ones marked slow."""
    return [pytest.param(c, id=c.name, marks=[pytest.mark.slow] if c.name in HUGE else []) for c in cases]


def _no_hang(seconds: int):
    """:func:`tests.helpers.no_hang`."""
    return no_hang(seconds)


def test_corpus_size_and_coverage():
    assert len(cb.CASES) >= 60
    assert len(cb.CASES_BY_NAME) == len(cb.CASES), "case names must be unique"
    assert HUGE <= set(cb.CASES_BY_NAME), "a case marked slow is gone"
    topics = collections.Counter(c.topic for c in cb.CASES)
    for topic in ("xml", "structure", "numbers", "inertials", "mesh_paths", "mesh_contents"):
        assert topics[topic] >= 5, topics
    unknown = [c.code for c in cb.CASES if c.code not in vi.CODES]
    assert unknown == []


def test_base_asset_is_valid(tmp_path):
    assert not vi.has_errors(vi.validate_asset(cb.build_valid(tmp_path / "a")))


@pytest.mark.parametrize("case", _tiered(cb.CASES))
def test_case_gets_its_code(case, tmp_path):
    asset = case.build(tmp_path / "asset")
    policy = vi.ValidationPolicy(**(case.policy or {}))
    before = tree_hashes(asset)
    with _no_hang(HANG_LIMIT_S):
        findings = vi.validate_asset(asset, policy)
    hits = [f for f in findings if f.code == case.code]
    assert hits, f"{case.name}: expected {case.code}, got {[f.describe() for f in findings]}"
    assert "INTERNAL_ERROR" not in {f.code for f in findings}
    for f in hits:
        assert f.file and f.message
    if case.refused:
        assert any(f.severity == "error" for f in hits), [f.describe() for f in hits]
    else:
        assert not vi.has_errors(findings), [f.describe() for f in findings if f.severity == "error"]
    # extraction (what refine calls first) agrees, and nothing was written
    with _no_hang(HANG_LIMIT_S):
        if case.refused:
            with pytest.raises(AssetError) as info:
                extract_asset_checked(asset, policy=policy)
            assert case.code in info.value.codes
            assert case.code in str(info.value)
        else:
            desc, found = extract_asset_checked(asset, policy=policy)
            assert case.code in {f.code for f in found}
            replaced = {f.link for f in found if f.action == "replace_with_estimate"}
            assert all(desc.link(n).given_inertial is None for n in replaced)
            if case.topic == "inertials" and vi.CODES[case.code].severity == "warning":
                assert replaced, "an invalid inertial must be marked for replacement"
    assert tree_hashes(asset) == before


# ----------------------------------------------------------------------------- validate agrees with refine

AGREEMENT = [c for c in cb.CASES if c.topic == "refine_agreement" and not c.policy]


@pytest.mark.parametrize("case", _tiered(AGREEMENT))
def test_refine_refuses_with_one_line_and_status_1(case, tmp_path, capsys):
    """What validate refuses, ``asset2sim refine`` refuses the same way: exit
    status 1, one line per problem (the first naming the case's code), no
    traceback, no hang (FIFOs)."""
    asset = case.build(tmp_path / "asset")
    before = tree_hashes(asset)
    with _no_hang(HANG_LIMIT_S):
        assert cli.main(["validate", str(asset), "--quiet"]) == 1
        capsys.readouterr()
        status = cli.main(["refine", str(asset), "--out", str(tmp_path / "out"), "--no-extras", "-q"])
    err = capsys.readouterr().err
    assert status == 1, err
    lines = [ln for ln in err.splitlines() if ln.startswith("asset2sim refine")]
    assert lines and case.code in lines[0], err
    assert len(set(lines)) == len(lines) and all(ln.startswith("asset2sim refine: ") for ln in err.splitlines() if ln), err
    assert "Traceback" not in err
    assert tree_hashes(asset) == before


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(cb.ACCEPTED))
def test_refine_handles_what_validate_accepts(name, tmp_path, capsys):
    """Symlinked mesh inside the folder, ``dir/../`` through an existing
    folder, a UTF-8 byte-order mark, a two-turn revolute limit, a continuous
    or a fixed lid joint: validate accepts them, refine writes an output
    whose URDF opens every mesh it names (each a regular file)."""
    asset = cb.ACCEPTED[name](tmp_path / "asset")
    assert not vi.has_errors(vi.validate_asset(asset))
    out = tmp_path / "out"
    with _no_hang(240):
        status = cli.main(["refine", str(asset), "--out", str(out), "--no-extras", "-q"])
    err = capsys.readouterr().err
    assert status in (0, 3), err
    assert "Traceback" not in err
    text = (out / "mobility.urdf").read_text()
    for fname in set(re.findall(r'filename="([^"]+)"', text)):
        p = out / fname
        assert p.is_file() and not p.is_symlink(), fname


def test_input_hash_covers_mtl_and_textures(tmp_path):
    asset = cb.build_valid(tmp_path / "asset")
    h0 = extract_asset_checked(asset)[0].input_hash
    (asset / "images" / "tex.png").write_bytes(cb.PNG_1PX + b"\0")
    h1 = extract_asset_checked(asset)[0].input_hash
    assert h1 != h0, "an edited texture must change the input hash"
    (asset / "meshes" / "base.mtl").write_text(cb.MTL + "Ks 0.1 0.1 0.1\n")
    h2 = extract_asset_checked(asset)[0].input_hash
    assert h2 not in (h0, h1), "an edited MTL must change the input hash"
    result = vi.run_validation(asset)
    names = sorted(p.name for p in result.material_files)
    assert names == ["base.mtl", "tex.png"]


def test_face_cap_counts_visual_only_meshes(tmp_path):
    """A visual-only mesh over the per-file cap is a warning for that file but
    counts in the asset's total (PyBullet and the renderer load it too)."""
    asset = cb.build_valid(tmp_path / "asset")
    (asset / "meshes" / "lid_visual.obj").write_text(cb.CUBE_V + cb.CUBE_F * 10)
    text = (asset / "mobility.urdf").read_text().replace("meshes/lid.obj", "meshes/lid_visual.obj", 1)
    (asset / "mobility.urdf").write_text(text)
    policy = vi.ValidationPolicy(max_mesh_faces=100, max_total_faces=100)
    found = vi.validate_asset(asset, policy)
    assert any(f.code == "MESH_TOO_MANY_FACES" and f.severity == "error" and f.values.get("total_faces") for f in found)


def test_default_caps_are_documented():
    doc = (ROOT / "docs" / "design" / "validation.md").read_text()
    pol = vi.DEFAULT_POLICY
    assert pol.max_total_faces == vi.MAX_TOTAL_FACES and f"{vi.MAX_TOTAL_FACES:,}" in doc
    assert pol.max_links == vi.MAX_LINKS == 128


# ----------------------------------------------------------------------------- validate agrees with refine: sizes and textures


def test_huge_coordinates_print_no_numpy_warning(tmp_path):
    """1e308 coordinates are refused by comparison, before any arithmetic:
    no RuntimeWarning (turned into an error here), no INTERNAL_ERROR."""
    import warnings

    asset = cb.CASES_BY_NAME["mesh_coordinate_1e308"].build(tmp_path / "asset")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        found = vi.validate_asset(asset)
    codes = {f.code for f in found if f.severity == "error"}
    assert "MESH_COORDINATE_IMPLAUSIBLE" in codes and "INTERNAL_ERROR" not in codes


def test_size_bounds_derive_from_the_overlay_scale_range_and_the_priors():
    from asset2sim.tasks.ingest import findings
    from asset2sim.prior_tables import MAX_PRIOR_DIM_M, load_priors
    from asset2sim.tasks.interpret.size_priors import target_size
    from asset2sim.schemas.overlay import SCALE_RANGE

    assert findings.MAX_COORDINATE == MAX_PRIOR_DIM_M / SCALE_RANGE[0] == vi.DEFAULT_POLICY.max_coordinate
    lo, hi = findings.asset_size_range()
    targets = []
    for name in load_priors().categories:
        for words in ("", "a tiny one", "a very large one"):
            d = sorted(target_size(name, words).dims, reverse=True)
            targets.append((d[0] * d[1]) ** 0.5)  # the size refine scales to (estimate.choose_scale)
    # every target lies inside the envelope: an asset of any size in [lo, hi] ...
    assert all(lo * SCALE_RANGE[1] * (1 - 1e-9) <= g <= hi * SCALE_RANGE[0] * (1 + 1e-9) for g in targets)
    # ... and the envelope is tight at both ends (the tiniest and the largest target)
    assert min(targets) / lo <= SCALE_RANGE[1] * (1 + 1e-9) and max(targets) / hi >= SCALE_RANGE[0] * (1 - 1e-9)


def test_texture_pixels_read_from_the_header_only(tmp_path):
    from asset2sim.tasks.ingest.mesh_checks import texture_header, texture_problem

    p = tmp_path / "t.png"
    p.write_bytes(cb.png_header(9000, 9000))  # 81 megapixels claimed, 60 bytes on disk
    header = texture_header(p, 1 << 20)
    assert (header.size, header.width, header.height) == (p.stat().st_size, 9000, 9000)
    code, msg = texture_problem(p, 1 << 20, 8192 * 8192)
    assert code == "TEXTURE_TOO_LARGE" and "9000 x 9000" in msg
    p.write_bytes(cb.png_header(100_000, 100_000))  # 10 gigapixels: beyond PIL's own bomb limit, still "too large"
    code, msg = texture_problem(p, 1 << 20, 8192 * 8192)
    assert code == "TEXTURE_TOO_LARGE" and "10000000000" in msg  # a 60-byte file: its pixels were never decoded
    p.write_bytes(cb.png_header(64, 64))
    assert texture_problem(p, 1 << 20, 8192 * 8192) is None
    assert texture_problem(p, 10, 8192 * 8192)[0] == "TEXTURE_TOO_LARGE"  # the file cap, by os.stat


def test_texture_that_is_a_fifo_never_blocks(tmp_path):
    import os

    from asset2sim.tasks.ingest.mesh_checks import texture_problem

    p = tmp_path / "t.png"
    os.mkfifo(p)
    with _no_hang(10):
        code, _ = texture_problem(p, 1 << 20, 1 << 20)
    assert code == "TEXTURE_UNREADABLE"


OTHER_FORMATS = [c for c in cb.CASES if c.topic == "other_formats"]


@pytest.mark.parametrize("case", OTHER_FORMATS, ids=[c.name for c in OTHER_FORMATS])
def test_refine_refuses_hostile_mjcf_and_usd_with_one_line(case, tmp_path, capsys):
    """An MJCF or USD input naming a file it may not read: ``asset2sim refine`` exits 1 with one line naming the
    code, no traceback, no hang (FIFOs), nothing written in the input or beside the output."""
    asset = case.build(tmp_path / "asset")
    before = tree_hashes(asset)
    with _no_hang(HANG_LIMIT_S):
        status = cli.main(["refine", str(asset), "--out", str(tmp_path / "out"), "--no-extras", "-q"])
    err = capsys.readouterr().err
    assert status == 1, err
    lines = [ln for ln in err.splitlines() if ln.startswith("asset2sim refine")]
    assert len(lines) == 1 and case.code in lines[0], err
    assert "Traceback" not in err
    assert tree_hashes(asset) == before and not (tmp_path / "out").exists()
