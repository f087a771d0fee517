"""bcad batch: local pool and Dask LocalCluster give the same results; failures, resume, sweeps."""

from __future__ import annotations

import json
import math
import os

import pytest
from typer.testing import CliRunner

from bcad.batch import BatchUsageError, apply_sweep, parse_sweep, plan_tasks, task_seed
from bcad.cli import app

from conftest import ONE_LINK_GRAPH, REPO

runner = CliRunner()

ONE_LINK = ONE_LINK_GRAPH + (
    "solver: {population: 8, max_samples: 256, posterior_samples: 5000, selection_samples: 1024, refine_samples: 256}\n"
)
TIMINGS = {"seconds"}


def _strip_timings(value):
    if isinstance(value, dict):
        return {k: _strip_timings(v) for k, v in value.items() if k not in TIMINGS and k != "timings"}
    if isinstance(value, list):
        return [_strip_timings(v) for v in value]
    return value


def _results(folder):
    return {path.name: _strip_timings(json.loads(path.read_text())) for path in sorted(folder.glob("*.json"))}


def _summary(folder):
    return [_strip_timings(json.loads(line)) for line in (folder / "summary.jsonl").read_text().splitlines()]


@pytest.fixture
def batch_files(write_problem):
    one_link = write_problem(ONE_LINK, "onelink.yaml")
    broken = write_problem("name: broken\nframes: [a\n", "broken.yaml")
    return [one_link, broken, REPO / "problems" / "clearance" / "2r.yaml"]


@pytest.fixture(scope="module")
def cluster():
    distributed = pytest.importorskip("dask.distributed")
    with distributed.LocalCluster(
        n_workers=2, processes=True, threads_per_worker=1, host="127.0.0.1", dashboard_address=None
    ) as local:
        yield local


def _batch(files, out, *extra):
    return runner.invoke(app, ["batch", *map(str, files), "--out", str(out), "--quiet", *extra])


def test_dask_cluster_gives_the_local_results_and_reports_the_broken_file(batch_files, tmp_path, cluster):
    sweep = ["--sweep", "links.free.distributions.tx.std=0.1,0.3"]
    local = _batch(batch_files[:2], tmp_path / "local", "--jobs", "2", *sweep)
    remote = _batch(batch_files[:2], tmp_path / "dask", "--scheduler", cluster.scheduler_address, *sweep)
    assert local.exit_code == remote.exit_code == 1  # the broken file failed ...
    results = _results(tmp_path / "local")
    assert results == _results(tmp_path / "dask")
    assert _summary(tmp_path / "local") == _summary(tmp_path / "dask")
    # ... and was reported, while every other problem was written.
    assert set(results) == {
        "onelink__std=0.1.json",
        "onelink__std=0.3.json",
        "broken__std=0.1.json",
        "broken__std=0.3.json",
    }
    assert results["broken__std=0.1.json"]["error"]["type"] == "invalid_input"
    assert "YAML syntax error" in results["broken__std=0.1.json"]["error"]["message"]
    # The sweep really changed the problem: the closing link's spread follows the swept std.
    for std in (0.1, 0.3):
        link = results[f"onelink__std={std}.json"]["posterior"]["links"]["measured"]
        assert link["std"][0] == pytest.approx(std, rel=0.05)
    statuses = {line["output"]: line["status"] for line in _summary(tmp_path / "local")}
    assert statuses == {
        "onelink__std=0.1.json": "ok",
        "onelink__std=0.3.json": "ok",
        "broken__std=0.1.json": "error",
        "broken__std=0.3.json": "error",
    }


def test_results_do_not_depend_on_order_or_worker_count(batch_files, tmp_path):
    files = [batch_files[0], batch_files[2]]
    assert _batch(files, tmp_path / "one", "--jobs", "1").exit_code == 0
    assert _batch(files[::-1], tmp_path / "two", "--jobs", "2").exit_code == 0
    assert _results(tmp_path / "one") == _results(tmp_path / "two")


def test_resume_does_not_recompute(batch_files, tmp_path):
    files = [batch_files[0], batch_files[2]]
    out = tmp_path / "out"
    assert _batch(files, out, "--jobs", "1").exit_code == 0
    stamps = {path.name: path.stat().st_mtime_ns for path in out.glob("*.json")}
    # A half-written result (as after a crash without atomic writes) is not complete.
    (out / "2r.json").write_text('{"problem": "rr-clear')
    assert _batch(files, out, "--jobs", "1", "--resume").exit_code == 0
    assert (out / "onelink.json").stat().st_mtime_ns == stamps["onelink.json"]
    assert json.loads((out / "2r.json").read_text())["problem"] == "rr-clearance"
    statuses = {line["output"]: line["status"] for line in _summary(out)}
    assert statuses == {"onelink.json": "skipped", "2r.json": "ok"}
    assert not list(out.glob(".*.tmp"))


def test_sweep_paths_reach_list_items_by_name_and_distribution_fields():
    data = {"links": [{"name": "ab", "distributions": {"tx": "normal(0, 0.3)"}}], "solver": {"population": 8}}
    swept = apply_sweep(
        data, (("links.ab.distributions.tx.std", 0.5), ("solver.population", 16), ("links.0.name", "cd"))
    )
    assert swept["links"][0]["distributions"]["tx"] == {"type": "normal", "mean": 0.0, "std": 0.5}
    assert swept["solver"]["population"] == 16 and swept["links"][0]["name"] == "cd"
    assert data["links"][0]["distributions"]["tx"] == "normal(0, 0.3)"  # the original is untouched
    assert parse_sweep("a.b=1,2.5,x").values == (1, 2.5, "x")


def test_seeds_come_from_the_name_and_point_only():
    assert task_seed(0, "a.yaml", ()) == task_seed(0, "a.yaml", ())
    assert task_seed(0, "a.yaml", ()) != task_seed(1, "a.yaml", ())
    assert task_seed(0, "a.yaml", (("k", 1),)) != task_seed(0, "a.yaml", (("k", 2),))


@pytest.mark.parametrize("extra", [["--sweep", "nonsense"], ["--jobs", "0"]])
def test_bad_command_lines_exit_2(batch_files, tmp_path, extra):
    result = _batch(batch_files[:1], tmp_path / "out", *extra)
    assert result.exit_code == 2
    assert "Traceback" not in result.output + result.stderr


def test_out_must_be_a_folder(batch_files, tmp_path):
    target = tmp_path / "file.txt"
    target.write_text("keep me")
    result = _batch(batch_files[:1], target)
    assert result.exit_code == 2 and target.read_text() == "keep me"


def test_missing_dask_scheduler_is_a_clear_error(batch_files, tmp_path, monkeypatch):
    import bcad.batch as batch

    monkeypatch.setattr(batch, "SCHEDULER_TIMEOUT", 1)  # dask retries a refused port until its timeout
    result = _batch(batch_files[:1], tmp_path / "out", "--scheduler", "tcp://127.0.0.1:1")
    assert result.exit_code == 2
    assert "cannot reach the Dask scheduler" in result.stderr
    assert os.path.isdir(tmp_path / "out")


def test_an_address_that_is_no_dask_scheduler_is_named_as_such(batch_files, tmp_path, monkeypatch):
    """A service that answers with HTTP: Dask read its bytes as a message and said "MemoryError:
    Unable to allocate 3.07 EiB"; the message now says no scheduler answers there."""
    pytest.importorskip("distributed")
    import socket
    import threading

    import bcad.batch as batch

    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(4)

    def answer() -> None:
        while True:
            try:
                connection, _ = server.accept()
            except OSError:
                return
            with connection:
                connection.recv(100)
                connection.sendall(b"HTTP/1.1 400 Bad Request\r\ncontent-length: 0\r\n\r\n")

    threading.Thread(target=answer, daemon=True).start()
    monkeypatch.setattr(batch, "SCHEDULER_TIMEOUT", 2)
    try:
        address = f"tcp://127.0.0.1:{server.getsockname()[1]}"
        result = _batch(batch_files[:1], tmp_path / "out", "--scheduler", address)
    finally:
        server.close()
    assert result.exit_code == 2
    assert f"no Dask scheduler answers at {address}" in result.stderr, result.stderr
    assert "EiB" not in result.stderr.split("(")[0]


def test_scheduler_without_dask_says_how_to_install(batch_files, tmp_path, monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "dask.distributed", None)  # import fails as if not installed
    result = _batch(batch_files[:1], tmp_path / "out", "--scheduler", "tcp://127.0.0.1:8786")
    assert result.exit_code == 2
    assert "pip install -e '.[dask]'" in result.stderr


def test_the_progress_bar_is_a_terminal_s_only(batch_files, tmp_path):
    """With stderr a file (or a pipe), the progress bar was written there all the same, unlike the
    other commands' (the guide says progress goes to a terminal only)."""
    from conftest import run_bcad

    run = run_bcad("batch", batch_files[0], "--out", tmp_path / "out", "--jobs", "1")
    assert run.returncode == 0, run.stderr
    assert "━" not in run.stderr and "1/1" not in run.stderr, run.stderr
    assert "1 of 1 problems done" in run.stderr


def test_missing_file_is_a_failed_problem_not_a_crash(batch_files, tmp_path):
    result = _batch([batch_files[2], tmp_path / "absent.yaml"], tmp_path / "out", "--jobs", "1")
    assert result.exit_code == 1
    document = json.loads((tmp_path / "out" / "absent.json").read_text())
    assert document["error"]["type"] == "invalid_input" and "no such file" in document["error"]["message"]
    assert json.loads((tmp_path / "out" / "2r.json").read_text())["problem"] == "rr-clearance"


def test_untrusted_results_have_status_warning_and_exit_3(tmp_path):
    # 50 posterior samples cannot give 100 effective samples: a written result with a warning.
    (tmp_path / "thin.yaml").write_text(
        ONE_LINK_GRAPH + "solver: {posterior_samples: 50, finalist_samples: 50}\n", encoding="utf-8"
    )
    (tmp_path / "fine.yaml").write_text(ONE_LINK_GRAPH, encoding="utf-8")
    out = tmp_path / "out"
    result = runner.invoke(
        app,
        [
            "batch",
            str(tmp_path / "thin.yaml"),
            str(tmp_path / "fine.yaml"),
            "--out",
            str(out),
            "--jobs",
            "1",
            "--quiet",
        ],
    )
    assert result.exit_code == 3, result.output
    lines = {json.loads(line)["file"]: json.loads(line) for line in (out / "summary.jsonl").read_text().splitlines()}
    assert lines["thin.yaml"]["status"] == "warning" and "few_effective_samples" in lines["thin.yaml"]["warnings"]
    assert lines["fine.yaml"]["status"] == "ok" and lines["fine.yaml"]["warnings"] == []
    assert json.loads((out / "thin.json").read_text())["warnings"]
    # the scored parameter's plain (Table 2) and weighted std, as the result has them
    link = json.loads((out / "fine.json").read_text())["posterior"]["links"]["measured"]
    assert lines["fine.yaml"]["constrained_std"] == {"measured": {"tx": link["std"][0]}}
    assert lines["fine.yaml"]["constrained_weighted_std"] == {"measured": {"tx": link["weighted"]["std"][0]}}
    assert link["weighted"]["std"][0] < link["std"][0]  # the score narrows it
    # --resume skips both, keeping what each result says and the seconds it took (they were
    # rewritten as skipped, 0.0 s, and the kept warning no longer made the batch exit 3)
    again = runner.invoke(
        app, ["batch", str(tmp_path / "thin.yaml"), str(tmp_path / "fine.yaml"), "--out", str(out), "--resume"]
    )
    assert again.exit_code == 3, again.output
    resumed = {json.loads(line)["file"]: json.loads(line) for line in (out / "summary.jsonl").read_text().splitlines()}
    for name, status in (("thin.yaml", "warning"), ("fine.yaml", "ok")):
        assert resumed[name]["status"] == "skipped" and resumed[name]["result_status"] == status
        assert resumed[name]["seconds"] == lines[name]["seconds"] > 0
        assert resumed[name]["warnings"] == lines[name]["warnings"]
    # an earlier summary edited by hand or by another program: its seconds are read or left out
    summary = out / "summary.jsonl"
    rows = [json.loads(line) for line in summary.read_text().splitlines()]
    rows[0]["seconds"], rows[1]["seconds"] = -1.0, "1" + "0" * 400
    text = "\n".join(json.dumps(row) for row in rows).replace('"1' + "0" * 400 + '"', "1" + "0" * 400)
    summary.write_text(text + "\n{not json\n[1, 2]\n")
    again = runner.invoke(
        app, ["batch", str(tmp_path / "thin.yaml"), str(tmp_path / "fine.yaml"), "--out", str(out), "--resume"]
    )
    assert again.exit_code == 3, again.output  # an OverflowError was an internal error (exit 1)
    assert all(json.loads(line)["seconds"] is None for line in summary.read_text().splitlines())


def test_readme_sweep_runs(tmp_path):
    """The README's sweep: a std of a distribution and a solver key the file lacks."""
    import re as _re

    from conftest import documentation

    readme = documentation()
    command = _re.search(r"bcad batch problems/studies/planar_2r\.yaml --out study \\\n\s+(.*)\n", readme).group(1)
    sweeps = _re.findall(r"--sweep (\S+)", command)
    args = [
        "batch",
        str(REPO / "problems" / "studies" / "planar_2r.yaml"),
        "--out",
        str(tmp_path / "study"),
        "--jobs",
        "1",
        "--quiet",
    ]
    for sweep in sweeps:
        key, values = sweep.split("=")
        args += ["--sweep", f"{key}={values.split(',')[0]}"]  # one point per sweep keeps the test short
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    line = json.loads((tmp_path / "study" / "summary.jsonl").read_text())
    assert line["status"] == "ok"


def test_resume_keeps_the_results_seed_and_cleans_temporaries(batch_files, tmp_path):
    out = tmp_path / "out"
    first = runner.invoke(
        app, ["batch", *map(str, batch_files), "--out", str(out), "--jobs", "1", "--quiet", "--seed", "1"]
    )
    assert first.exit_code in (0, 1)
    first_seeds = {
        json.loads(line)["output"]: json.loads(line)["seed"]
        for line in (out / "summary.jsonl").read_text().splitlines()
    }
    stale = out / f".{next(iter(first_seeds))}.bcad-999999999.tmp"  # a killed writer's, of a result this batch writes
    stale.write_text("{")
    foreign = out / ".ghost.json.999999999.tmp"  # not bcad's: kept
    foreign.write_text("{")
    again = runner.invoke(
        app, ["batch", *map(str, batch_files), "--out", str(out), "--jobs", "1", "--quiet", "--seed", "2", "--resume"]
    )
    assert again.exit_code in (0, 1)
    assert not stale.exists() and foreign.exists()
    for line in (out / "summary.jsonl").read_text().splitlines():
        line = json.loads(line)
        result = json.loads((out / line["output"]).read_text())
        if line["status"] == "skipped" and "seed" in result:  # maxerror results use no seed
            assert line["seed"] == result["seed"] == first_seeds[line["output"]]


def test_resume_recomputes_a_result_lacking_keys(batch_files, tmp_path):
    out = tmp_path / "out"
    runner.invoke(app, ["batch", *map(str, batch_files), "--out", str(out), "--jobs", "1", "--quiet"])
    victim = next(path for path in out.glob("*.json") if "error" not in json.loads(path.read_text()))
    document = json.loads(victim.read_text())
    document.pop("objective", None) or document.pop("rotation", None)
    victim.write_text(json.dumps(document))
    again = runner.invoke(
        app, ["batch", *map(str, batch_files), "--out", str(out), "--jobs", "1", "--quiet", "--resume"]
    )
    assert "Traceback" not in again.output and again.exit_code in (0, 1)
    restored = json.loads(victim.read_text())
    assert "objective" in restored or "rotation" in restored


def test_out_below_a_file_is_a_usage_error(batch_files, tmp_path):
    (tmp_path / "afile").write_text("x")
    result = runner.invoke(app, ["batch", str(batch_files[0]), "--out", str(tmp_path / "afile" / "sub"), "--quiet"])
    assert result.exit_code == 2 and "cannot create --out" in result.output


def test_a_dead_worker_restarts_the_pool_and_the_other_tasks_still_run(write_problem, tmp_path):
    from batch_crash import crash_once

    from bcad.batch import _run_on_pool, plan_tasks

    files = [
        write_problem(ONE_LINK, "crash.yaml"),
        write_problem(ONE_LINK, "fine.yaml"),
        REPO / "problems" / "clearance" / "2r.yaml",
    ]
    out = tmp_path / "out"
    out.mkdir()
    tasks = plan_tasks(files, out, 0, [])
    recorded = {}
    _run_on_pool(
        tasks, list(range(len(tasks))), 2, lambda index, document, line: recorded.__setitem__(index, line), crash_once
    )
    assert sorted(recorded) == [0, 1, 2]
    assert [recorded[index]["status"] for index in range(3)] == ["ok", "ok", "ok"]


def test_a_task_past_its_timeout_is_recorded_and_the_batch_goes_on(write_problem, tmp_path):
    slow = write_problem(
        ONE_LINK_GRAPH + "solver: {estimator: mc, max_samples: 400000, initial_samples: 1000}\n",
        "slow.yaml",
    )
    quick = REPO / "problems" / "clearance" / "2r.yaml"
    out = tmp_path / "out"
    result = runner.invoke(
        app, ["batch", str(slow), str(quick), "--out", str(out), "--jobs", "1", "--quiet", "--timeout", "1"]
    )
    assert result.exit_code == 1
    lines = {json.loads(line)["file"]: json.loads(line) for line in (out / "summary.jsonl").read_text().splitlines()}
    assert lines["slow.yaml"]["error"]["type"] == "timeout" and lines["slow.yaml"]["seconds"] < 5
    assert lines["2r.yaml"]["status"] == "ok"


@pytest.mark.parametrize("address", ["notaurl", "inproc://x", "tcp://host"])
def test_bad_scheduler_addresses_exit_2(batch_files, tmp_path, address):
    result = runner.invoke(
        app, ["batch", str(batch_files[0]), "--out", str(tmp_path / "o"), "--scheduler", address, "--quiet"]
    )
    assert result.exit_code == 2 and "--scheduler" in result.output


@pytest.mark.skipif(not os.path.isdir("/proc"), reason="reads /proc")
def test_pool_workers_exit_when_the_batch_is_killed(write_problem, tmp_path):
    import signal
    import subprocess
    import sys
    import time

    slow = [
        write_problem(
            ONE_LINK_GRAPH + "solver: {estimator: mc, max_samples: 400000, initial_samples: 1000}\n",
            f"slow{k}.yaml",
        )
        for k in range(2)
    ]
    batch = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "bcad.cli",
            "batch",
            *map(str, slow),
            "--out",
            str(tmp_path / "o"),
            "--jobs",
            "2",
            "--quiet",
        ]
    )

    def children(pid):
        found = []
        for entry in os.listdir("/proc"):
            if entry.isdigit():
                try:
                    fields = open(f"/proc/{entry}/stat").read().rsplit(")", 1)[1].split()
                except OSError:
                    continue
                if int(fields[1]) == pid:
                    found.append(int(entry))
        return found

    deadline = time.time() + 30
    while len(children(batch.pid)) < 2 and time.time() < deadline:
        time.sleep(0.2)
    workers = children(batch.pid)
    assert workers, "the pool never started"
    time.sleep(1.0)
    batch.send_signal(signal.SIGKILL)
    batch.wait()
    deadline = time.time() + 15
    while (
        any(
            os.path.exists(f"/proc/{pid}") and "Z" not in open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()[0]
            for pid in workers
        )
        and time.time() < deadline
    ):
        time.sleep(0.2)
    alive = [
        pid
        for pid in workers
        if os.path.exists(f"/proc/{pid}") and open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()[0] != "Z"
    ]
    for pid in alive:  # leave no orphan behind, whatever the outcome
        os.kill(pid, signal.SIGKILL)
    assert not alive


def test_sweep_values_are_read_as_a_user_means_them():
    assert parse_sweep("a.b=1e-4,-1.2,2,abc").values == (1e-4, -1.2, 2, "abc")
    with pytest.raises(Exception, match="finite"):
        parse_sweep("a.b=nan")
    with pytest.raises(BatchUsageError, match="cannot read the value '9999"):  # beyond Python's int conversion
        parse_sweep("a.b=" + "9" * 5000)


@pytest.mark.parametrize("sizes", [(1000, 1000), (300, 300, 300)])
def test_a_grid_beyond_the_batch_limit_is_refused_at_once(tmp_path, sizes):
    problem = tmp_path / "one.yaml"
    problem.write_text(ONE_LINK_GRAPH)
    keys = ["solver.search_starts", "solver.search_climbs", "solver.finalists"]
    sweeps = [parse_sweep(f"{key}=" + ",".join(str(k + 1) for k in range(size))) for key, size in zip(keys, sizes)]
    with pytest.raises(BatchUsageError, match=f"make {math.prod(sizes):,} runs; a batch runs at most 10,000"):
        plan_tasks([problem], tmp_path / "out", 0, sweeps)


def test_a_scheduler_that_never_answers_exits_2(batch_files, tmp_path, monkeypatch):
    """A loopback server that accepts connections and says nothing (bounded: it stops itself)."""
    pytest.importorskip("dask.distributed")
    import socket
    import threading
    import time

    import bcad.batch as batch

    monkeypatch.setattr(batch, "SCHEDULER_TIMEOUT", 1)
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(5)
    server.settimeout(0.2)
    stop = time.time() + 20
    held = []

    def accept() -> None:
        while time.time() < stop:
            try:
                held.append(server.accept()[0])
            except OSError:
                pass
        for connection in held:
            connection.close()
        server.close()

    threading.Thread(target=accept, daemon=True).start()
    start = time.time()
    address = f"tcp://127.0.0.1:{server.getsockname()[1]}"
    result = runner.invoke(
        app, ["batch", str(batch_files[0]), "--out", str(tmp_path / "o"), "--scheduler", address, "--quiet"]
    )
    assert result.exit_code == 2 and "did not answer" in result.output
    assert time.time() - start < 10


@pytest.mark.parametrize("value, says", [("abc", "valid number"), ("-0.01", "greater than or equal to 1e-12")])
def test_a_sweep_value_the_schema_refuses_is_the_command_lines_error(tmp_path, value, says):
    """A swept std of 'abc' or -0.01: refused before anything runs (exit 2), named as the --sweep's,
    not placed at the file's valid value it replaces."""
    out = tmp_path / "study"
    sweep = f"links.zero2.distributions.rz.std=0.01,{value}"
    problem = REPO / "problems" / "studies" / "planar_2r.yaml"
    result = runner.invoke(app, ["batch", str(problem), "--out", str(out), "--sweep", sweep, "--jobs", "1"])
    assert result.exit_code == 2, result.output
    assert f"--sweep links.zero2.distributions.rz.std={value}: planar_2r.yaml does not take it" in result.output
    assert says in result.output and "planar_2r.yaml:" not in result.output
    assert not out.exists() or not any(out.glob("*.json"))  # nothing ran


def test_a_misspelt_field_in_a_sweep_or_a_file_is_named_with_the_closest_one(tmp_path):
    """A distribution's unknown field (std misspelt stdd) read "Extra inputs are not permitted" from
    a --sweep, and "missing key 'std'" from a file; both now name it and the field meant."""
    problem = REPO / "problems" / "studies" / "planar_2r.yaml"
    sweep = "links.zero2.distributions.rz.stdd=0.01"
    result = runner.invoke(app, ["batch", str(problem), "--out", str(tmp_path / "o"), "--sweep", sweep])
    assert result.exit_code == 2, result.output
    assert "unknown key 'stdd'; did you mean 'std'?" in result.output and "Extra inputs" not in result.output
    typo = tmp_path / "typo.yaml"
    typo.write_text(problem.read_text().replace("rz: 'normal(0, 0.05)'", "rz: {type: normal, mean: 0, stdd: 0.05}"))
    result = runner.invoke(app, ["validate", str(typo)])
    assert result.exit_code == 2 and "unknown key 'stdd'; did you mean 'std'?" in result.output, result.output


def test_a_file_the_schema_refuses_is_its_runs_error_with_a_sweep_too(tmp_path):
    """A broken file among good ones, with a sweep: its runs report it (exit 1), the sweep is not
    blamed for it."""
    good = REPO / "problems" / "studies" / "planar_2r.yaml"
    broken = tmp_path / "broken.yaml"
    broken.write_text(good.read_text().replace("name: planar-2r", "name: planar-2r\nnot_a_key: 1"))
    out = tmp_path / "study"
    result = runner.invoke(
        app,
        ["batch", str(broken), "--out", str(out), "--sweep", "links.zero2.distributions.rz.std=0.01", "--jobs", "1"],
    )
    assert result.exit_code == 1, result.output
    assert "does not take it" not in result.output
