"""The benchmark reads the manifest row by row: a malformed row becomes an
error record (skipped, reported), the other rows are benchmarked."""

from __future__ import annotations

import pytest

from asset2sim.apps.benchmark import benchmark
from asset2sim.tasks.ingest import partnet_mobility
from tests.apps.benchmark.test_baselines import dataset  # noqa: F401  (the generated dataset fixture)


def test_a_malformed_manifest_row_is_reported_and_the_others_run(dataset, tmp_path):  # noqa: F811
    manifest = dataset / "manifest.csv"
    huge = "open " * 40_000  # 200,000 characters: beyond the CSV field limit
    manifest.write_text(manifest.read_text() + f'big,Box,"{huge}",,,0.5,\n' + "../evil,Box,open it,,,0.5,\n")
    said = []
    records = benchmark.run_benchmark(manifest, ["defaults"], tmp_path / "bench", reports=False,
                                      progress=lambda m, i, msg: said.append((i, msg)))
    by = {r["id"]: r for r in records}
    assert set(by) == {"1001", "big", "../evil"}
    assert by["1001"]["error"] is None and (tmp_path / "bench" / "defaults" / "1001" / "evaluation.json").is_file()
    assert by["big"]["error"].startswith("manifest row MANIFEST_ROW_TOO_LARGE")
    assert by["../evil"]["error"].startswith("manifest row MANIFEST_INVALID_ID")
    assert all(r["thesis_set"] for r in records)  # all among the first nine rows of the file
    assert [i for i, _ in said] == ["1001", "big", "../evil"]  # reported, in manifest order
    assert benchmark.summarize(records, ["defaults"])["defaults"]["errors"] == 2
    assert not (tmp_path / "bench" / "defaults" / "big").exists()
    manifest.write_text("name,request\nx,y\n")  # not a manifest at all: refused as a whole
    with pytest.raises(partnet_mobility.ManifestError, match="missing column"):
        benchmark.run_benchmark(manifest, ["defaults"], tmp_path / "bench2", reports=False)
