"""The seeded fuzz sample of CI (a few hundred cases per target) and the harness's own checks.

The full run is ``python scripts/fuzz.py`` (10,000 cases per parser); see tests/fuzz/.
A failing case is saved under the test's tmp folder, named in the failure message.
"""

from __future__ import annotations

import pytest

from fuzz.harness import run_cases, run_target, failure_lines, load_target

SEED = 0
# Cases per target: a few hundred where a case takes milliseconds, fewer where it runs a whole command.
SAMPLE = {"bvh": 200, "audio": 120, "midi": 300, "toml": 300, "database": 150, "cli": 30, "web": 100,
          "character_gltf": 90, "character_vrm": 90, "character_bvh": 150, "character_bonemap": 150}


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    return tmp_path_factory.mktemp("fuzz")


@pytest.mark.parametrize("target", list(SAMPLE))
def test_fuzz_sample_has_only_sane_outcomes(target, workdir, tmp_path):
    result = run_target(target, SAMPLE[target], SEED, workdir / target, failures_dir=tmp_path / "failures")
    assert result.cases == SAMPLE[target]
    assert not result.failures, f"{target}: inputs that were not sane or our error:\n{failure_lines([result])}"


def test_harness_sorts_outcomes_and_survives_hangs_and_blow_ups(tmp_path):
    spec = "fuzz.selftest_target:TARGET"
    cases = load_target(spec).cases(8, SEED, tmp_path)
    # hang_s leaves the blow-up many times the second it needs on a loaded machine (load 8 on 2 cores)
    result = run_cases("selftest", spec, cases, tmp_path, hang_s=8.0, memory_mb=600.0)
    assert result.counts == {"ok": 3, "input_error": 1, "other_exception": 1, "insane_output": 1, "hang": 1,
                             "memory": 1}
    kinds = {f.kind: f for f in result.failures.values()}
    assert "ValueError" in kinds["other_exception"].key and "selftest_target.py" in kinds["other_exception"].key
    assert kinds["hang"].examples == [4] and kinds["memory"].examples == [6]
    # the cases after the hang and the blow-up ran in a fresh child and were ok
    assert result.peak_rss_mb > 600.0
