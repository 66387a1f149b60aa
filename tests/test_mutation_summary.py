"""The mutation summary (scripts/mutation_modules.py): what docs/mutation.md shows of the cached results.

Oracle: hand-made cache files with known counts.  A current result is a row and counts in the total; a result
whose fingerprint no longer matches (its module or a selected test changed) is a row marked stale, out of the
total; a module without a result is listed as not run.
"""

from __future__ import annotations

import json


def _result(module: str, fingerprint: str, statuses: list[str]) -> dict:
    return {"module": module, "fingerprint": fingerprint, "date": "2026-12-03T10:00:00+00:00",
            "results": {f"{module}.x__mutmut_{i}": st for i, st in enumerate(statuses)}, "diffs": {}}


def test_stale_results_are_shown_marked_and_left_out_of_the_total(load_script, tmp_path, monkeypatch) -> None:
    mm = load_script("mutation_modules")
    monkeypatch.setattr(mm, "CACHE", tmp_path)
    monkeypatch.setattr(mm, "equivalents", dict)
    current, stale, missing = "twin.physics.fillet", "twin.physics.motion", "twin.model.fe"
    (tmp_path / f"{current}.json").write_text(json.dumps(
        _result(current, mm.fingerprint(current), ["killed", "killed", "killed", "survived"])))
    (tmp_path / f"{stale}.json").write_text(json.dumps(
        _result(stale, "0" * 64, ["killed", "survived", "survived", "survived", "no tests"])))
    text = mm.summary([current, stale, missing])
    rows = {line.split(" | ")[0].strip("| "): line for line in text.splitlines() if line.startswith("| ")}
    assert "| 75.0 % | 2026-12-03 |" in rows[current]
    assert "| 20.0 % | 2026-12-03 (stale) |" in rows[stale]  # as measured then, marked
    assert "| **current results** | 4 | 3 | 0 | 1 |" in rows["**current results**"]  # the stale row is not in it
    assert "**75.0 %**" in rows["**current results**"]
    assert missing not in rows
    stale_list = text.split("Stale (")[1].split("Not run (")[0]
    assert f"- {stale}" in stale_list and f"- {missing}" not in stale_list
    assert f"- {missing}" in text.split("Not run (")[1]


def _project(root, selection: list[str]) -> None:
    (root / "pyproject.toml").write_text(
        "[tool.mutmut]\nonly_mutate = ['twin/fake.py']\npytest_add_cli_args_test_selection = ["
        + ", ".join(f"'{t}'" for t in selection) + "]\n")


def test_a_result_is_stale_only_when_its_module_or_the_tests_that_covered_it_change(load_script, tmp_path,
                                                                                    monkeypatch) -> None:
    """Per-module fingerprints: a test file added to the selection does not stale a result it did not cover (the
    whole-selection hash of stop 35 staled every result at once); an edit of a covering test or of the module does.
    A result stored under the old rule and still current under it is migrated to the per-module one."""
    mm = load_script("mutation_modules")
    monkeypatch.setattr(mm, "ROOT", tmp_path)
    monkeypatch.setattr(mm, "CACHE", tmp_path / ".mutation-cache")
    (tmp_path / "twin").mkdir()
    (tmp_path / "tests").mkdir()
    (tmp_path / ".mutation-cache").mkdir()
    (tmp_path / "mutants").mkdir()
    (tmp_path / "twin" / "fake.py").write_text("def f():\n    return 1\n")
    (tmp_path / "tests" / "test_a.py").write_text("def test_1():\n    assert True\n")
    (tmp_path / "tests" / "test_b.py").write_text("def test_2():\n    assert True\n")
    (tmp_path / "mutants" / "mutmut-stats.json").write_text(json.dumps(
        {"tests_by_mangled_function_name": {"twin.fake.x_f": ["tests/test_a.py::test_1"],
                                            "twin.other.x_g": ["tests/test_b.py::test_2"]}}))
    _project(tmp_path, ["tests/test_a.py"])
    module = "twin.fake"
    assert mm.covering_tests(module) == ["tests/test_a.py"]
    old_rule = _result(module, mm.fingerprint(module), ["killed", "survived"])  # stored before stop 36
    mm._cache_file(module).write_text(json.dumps(old_rule))
    assert mm.migrate(module)
    assert json.loads(mm._cache_file(module).read_text())["tests"] == ["tests/test_a.py"]
    assert mm.cached(module) is not None
    _project(tmp_path, ["tests/test_a.py", "tests/test_b.py"])  # one more selected file, not covering it
    assert mm.cached(module) is not None
    assert not mm.migrate(module)  # already per module
    (tmp_path / "tests" / "test_a.py").write_text("def test_1():\n    assert 1 == 1\n")  # a covering test edited
    assert mm.cached(module) is None
    (tmp_path / "tests" / "test_a.py").write_text("def test_1():\n    assert True\n")
    assert mm.cached(module) is not None
    (tmp_path / "twin" / "fake.py").write_text("def f():\n    return 2\n")  # the module edited
    assert mm.cached(module) is None


def test_revalidate_keeps_only_what_was_measured_with_the_same_module_and_covering_tests(load_script, tmp_path,
                                                                                         monkeypatch) -> None:
    """``--revalidate COMMIT``: a result staled by a selection change (stop 35's rule) is kept only if the module
    and every test covering it now were the same, and selected, on the commit it was measured on."""
    import subprocess

    mm = load_script("mutation_modules")
    monkeypatch.setattr(mm, "ROOT", tmp_path)
    monkeypatch.setattr(mm, "CACHE", tmp_path / ".mutation-cache")
    for d in ("twin", "tests", ".mutation-cache", "mutants"):
        (tmp_path / d).mkdir()
    (tmp_path / "twin" / "fake.py").write_text("def f():\n    return 1\n")
    (tmp_path / "tests" / "test_a.py").write_text("def test_1():\n    assert True\n")
    (tmp_path / "tests" / "test_b.py").write_text("def test_2():\n    assert True\n")
    _project(tmp_path, ["tests/test_a.py"])
    git = ["git", "-c", "user.name=t", "-c", "user.email=t@t", "-C", str(tmp_path)]
    subprocess.run([*git, "init", "-q"], check=True)
    subprocess.run([*git, "add", "-A"], check=True)
    subprocess.run([*git, "commit", "-qm", "measured here"], check=True)
    module = "twin.fake"
    stored = _result(module, mm.fingerprint(module), ["killed", "survived"])  # the old rule, on this commit

    def stats(covering: list[str]) -> None:
        (tmp_path / "mutants" / "mutmut-stats.json").write_text(json.dumps(
            {"tests_by_mangled_function_name": {"twin.fake.x_f": covering}}))

    def attempt() -> bool:
        mm._cache_file(module).write_text(json.dumps(stored))
        return mm.revalidate(module, "HEAD")

    _project(tmp_path, ["tests/test_a.py", "tests/test_b.py"])  # the selection grew: stale by the old rule
    assert mm.cached(module) is None
    stats(["tests/test_b.py::test_2"])  # covered now by a test that was not selected then
    assert not attempt()
    stats(["tests/test_a.py::test_1"])
    measured_elsewhere = stored
    stored = {**stored, "fingerprint": "0" * 64}  # not measured on this commit's files
    assert not attempt()
    stored = measured_elsewhere
    assert attempt() and mm.cached(module) is not None
    (tmp_path / "tests" / "test_a.py").write_text("def test_1():\n    assert 1 == 1\n")  # the covering test differs
    assert not attempt()
    (tmp_path / "tests" / "test_a.py").write_text("def test_1():\n    assert True\n")
    (tmp_path / "twin" / "fake.py").write_text("def f():\n    return 2\n")  # the module differs
    assert not attempt()
