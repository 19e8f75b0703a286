"""issue 27: several configs at once on one shared pool (estim.engine.scheduler), longest first, an
analysis that times itself alone, and the same tables as one config after another."""

import json
import os
import threading
import time

import pytest
import yaml
from click.testing import CliRunner
from test_cli import fake_project, tiny_config
from test_hostile import interruptible, started

from estim.cli.main import main
from estim.cli.output import longest_first
from estim.config.loading import load_file
from estim.config.registry import ANALYSES
from estim.engine import scheduler
from estim.util.workunits import execution, map_tasks


class Log:
    """What the work did, in order, from every thread."""

    def __init__(self) -> None:
        self.events: list[tuple[str, str]] = []
        self.lock = threading.Lock()

    def work(self, item: str, seconds: float = 0.02) -> str:
        with self.lock:
            self.events.append(("start", item))
        time.sleep(seconds)
        if item.startswith("fail"):
            raise RuntimeError(item)
        with self.lock:
            self.events.append(("end", item))
        return item.upper()


def test_every_item_runs_once_started_in_the_order_given():
    log = Log()
    items = [f"c{i}" for i in range(7)]
    got = dict(scheduler.run_each(items, log.work, threads=3))
    assert got == {i: i.upper() for i in items}
    assert [i for kind, i in log.events if kind == "start"][:3] == ["c0", "c1", "c2"]
    one = Log()
    list(scheduler.run_each(items, one.work, threads=1))
    assert [i for kind, i in one.events if kind == "start"] == items


def test_an_item_that_runs_alone_waits_for_the_others_and_has_the_machine_to_itself():
    log = Log()
    items = ["timing", "a", "b", "c", "d"]
    got = [i for i, _ in scheduler.run_each(items, log.work, threads=2,
                                            alone=lambda i: i == "timing")]
    assert got[-1] == "timing" and sorted(got) == sorted(items)
    start = log.events.index(("start", "timing"))
    assert sum(kind == "end" for kind, _ in log.events[:start]) == 4
    assert log.events[start + 1] == ("end", "timing")


def test_the_first_failure_stops_the_rest_and_is_raised():
    log = Log()
    stopped = []
    seen = []
    with pytest.raises(RuntimeError, match="fail-1"):
        for item, _ in scheduler.run_each(["ok", "fail-1", "later", "last"], log.work,
                                          threads=1, on_error=lambda: stopped.append(1)):
            seen.append(item)
    assert seen == ["ok"] and stopped == [1]
    assert ("start", "later") not in log.events and ("start", "last") not in log.events


def _pid_and_square(x: int) -> tuple[int, int]:
    return os.getpid(), x * x


def test_map_tasks_sends_its_tasks_to_the_shared_pool():
    with scheduler.process_pool(2) as pool, execution(pool=pool):
        done = map_tasks(_pid_and_square, range(6), jobs=1)
    assert [v for _, v in done] == [x * x for x in range(6)]
    assert os.getpid() not in {pid for pid, _ in done}


def test_longest_first_follows_the_recorded_wall_times(tmp_path):
    exps = []
    for name, seconds in (("short", 2.0), ("long", 90.0), ("new", None), ("mid", 30.0)):
        spec = tiny_config(name=name)
        path = tmp_path / f"{name}.yaml"
        path.write_text(yaml.safe_dump(spec))
        exps.append(load_file(path))
        if seconds is not None:
            (tmp_path / "res" / name).mkdir(parents=True)
            (tmp_path / "res" / name / "run.json").write_text(
                json.dumps({"wall_time_s": seconds}))
    assert [e.name for e in longest_first(exps, tmp_path / "res")] == ["new", "long", "mid",
                                                                      "short"]
    # a fresh clone has no run records: the stored wall_times.csv stands in for them
    (tmp_path / "res" / "new").mkdir()
    (tmp_path / "res" / "wall_times.csv").write_text("name,wall_time_s\nnew,10.0\nmid,95.0\n")
    assert [e.name for e in longest_first(exps, tmp_path / "res")] == ["long", "mid", "new",
                                                                      "short"]


def test_only_the_timing_analysis_runs_alone():
    assert [name for name in ANALYSES if getattr(ANALYSES[name], "RUNS_ALONE", False)] == [
        "burden"]


@pytest.mark.slow
def test_reproduce_on_a_shared_pool_writes_what_one_config_after_another_writes(
        tmp_path, monkeypatch):
    root = fake_project(tmp_path, monkeypatch)
    (root / "configs" / "tiny2.yaml").write_text(yaml.safe_dump(
        tiny_config(name="tiny2", **{"monte_carlo.seed": 7, "monte_carlo.runs": 2})))
    runner = CliRunner()
    alone = runner.invoke(main, ["reproduce", "--jobs", "1", "--quiet", "--out",
                                 str(tmp_path / "one")])
    assert alone.exit_code == 0, alone.output
    shared = runner.invoke(main, ["reproduce", "--jobs", "2", "--out", str(tmp_path / "two")])
    assert shared.exit_code == 0, shared.output
    for name in ("tiny", "tiny2"):
        assert f"{name} -> {tmp_path / 'two' / name}" in shared.output
        for table in (tmp_path / "one" / name).glob("*.csv"):
            assert table.read_bytes() == (tmp_path / "two" / name / table.name).read_bytes()
        figures = sorted(p.name for p in (tmp_path / "one" / name / "figures").iterdir())
        assert figures and figures == sorted(
            p.name for p in (tmp_path / "two" / name / "figures").iterdir())
    checked = runner.invoke(main, ["check", "--jobs", "2", "--results", str(tmp_path / "two")])
    assert checked.exit_code == 0, checked.output
    lines = [line for line in checked.output.splitlines() if "rows match" in line]
    names = [line.split("/")[0] for line in lines]
    assert sorted(set(names)) == ["tiny", "tiny2"]
    assert names == sorted(names, key=names.index)          # each config's lines together
    assert checked.output.rstrip().endswith("check: all tables match")


def test_ctrl_c_during_a_shared_reproduce_is_one_line_exit_130_and_stops_the_workers(
        tmp_path):
    import signal
    import subprocess
    import sys

    root = tmp_path / "proj"
    (root / "configs").mkdir(parents=True)
    (root / "pyproject.toml").write_text('[project]\nname = "estim"\n')
    for name in ("slow", "slower"):
        spec = tiny_config(name=name, **{"monte_carlo.runs": 200, "input.periods": 40,
                                         "input.frequencies_hz": [100, 1000, 10000]})
        (root / "configs" / f"{name}.yaml").write_text(yaml.safe_dump(spec))
    out = tmp_path / "out"
    run = subprocess.Popen([sys.executable, "-m", "estim.cli.main", "reproduce", "--jobs", "2",
                            "--out", str(out)], cwd=root, stdout=subprocess.PIPE,
                           stderr=subprocess.PIPE, text=True, preexec_fn=interruptible)
    assert run.stderr.readline().strip().endswith(f"results in {out}/")
    assert "work units" in started(run)       # the computation has started
    time.sleep(1.0)
    run.send_signal(signal.SIGINT)
    assert run.wait(timeout=60) == 130
    rest = [line for line in run.stderr.read().splitlines() if "work units" not in line]
    assert rest == ["error: interrupted"], rest
    assert not (out / "slow").exists() and not (out / "slower").exists()
    time.sleep(0.5)
    left = subprocess.run(["pgrep", "-f", f"--out {out}"], capture_output=True, text=True)
    assert left.stdout.strip() == "", left.stdout


@pytest.fixture
def armed():
    """This process as the console script leaves it: its interrupt handler armed (and no
    interrupt recorded afterwards, for the tests that follow in this worker)."""
    from estim.util import interrupt

    interrupt.ARMED[0] = True
    yield interrupt
    interrupt.INTERRUPTED[0] = interrupt.ARMED[0] = False


def test_an_interrupt_python_swallowed_is_raised_where_the_drivers_are_waited_for(armed):
    """A Ctrl-C whose KeyboardInterrupt was lost (recorded by the handler, raised nowhere)
    still stops the wait for the drivers: it is raised while a driver's work is still
    running (that work waits for the test to let it go)."""
    release, finished = threading.Event(), threading.Event()

    def work(item):
        if item == "a":
            armed.INTERRUPTED[0] = True         # what the handler records
            return item
        release.wait(60.0)
        finished.set()
        return item

    try:
        with pytest.raises(KeyboardInterrupt):
            list(scheduler.run_each(["a", "b"], work, threads=2))
        assert not finished.is_set()            # raised before the running work ended
    finally:
        release.set()


def test_an_interrupt_python_swallowed_stops_map_tasks_before_the_next_unit(armed):
    done = []

    def unit(i):
        done.append(i)
        armed.INTERRUPTED[0] = True
        return i

    with pytest.raises(KeyboardInterrupt):
        map_tasks(unit, range(4))
    assert done == [0]


def test_python_swallows_an_interrupt_inside_a_lazy_import_and_estim_raises_it(tmp_path):
    """CPython 3.11 clears an error raised while its import statement reads a lazily loaded
    module's ``__spec__``: a SIGINT that lands while the module runs is lost there. The
    handler has recorded it, and the next place estim waits (here, importing the rest of the
    lazy modules) raises it."""
    import subprocess
    import sys

    (tmp_path / "slowmod.py").write_text(
        "import os, signal\nos.kill(os.getpid(), signal.SIGINT)\nVALUE = 1\n")
    child = "\n".join([
        "import signal, sys",
        f"sys.path.insert(0, {str(tmp_path)!r})",
        "from estim.util import interrupt, lazy",
        "signal.signal(signal.SIGINT, interrupt.on_interrupt)",
        "interrupt.arm()",
        "lazy.load('slowmod')",
        "import slowmod",
        "print('went on', interrupt.interrupted())",
        "try:",
        "    lazy.import_all_now()",
        "except KeyboardInterrupt:",
        "    print('raised')"])
    done = subprocess.run([sys.executable, "-c", child], capture_output=True, text=True,
                          timeout=60, preexec_fn=interruptible)
    assert done.stdout.split("\n")[:2] == ["went on True", "raised"], done.stderr


@pytest.mark.slow
def test_run_of_several_configs_shares_the_pool_and_writes_what_jobs_1_writes(tmp_path):
    paths = []
    for name, seed in (("first", 1), ("second", 2)):
        path = tmp_path / f"{name}.yaml"
        path.write_text(yaml.safe_dump(tiny_config(name=name, **{"monte_carlo.seed": seed})))
        paths.append(str(path))
    runner = CliRunner()
    tables = {}
    for jobs in ("1", "2"):
        out = tmp_path / f"jobs{jobs}"
        done = runner.invoke(main, ["run", *paths, "monte_carlo.runs=2", "--jobs", jobs,
                                    "--figure-format", "svg", "--out", str(out)])
        assert done.exit_code == 0, done.output
        assert "first -> " in done.output and "second -> " in done.output
        assert len(list((out / "second" / "figures").glob("*.svg"))) >= 1
        manifest = json.loads((out / "first" / "manifest.json").read_text())
        assert manifest["overrides"] == {"monte_carlo.runs": 2}
        tables[jobs] = {p.relative_to(out): p.read_bytes() for p in sorted(out.glob("*/*.csv"))}
    assert tables["1"] and tables["1"] == tables["2"]


def test_import_all_now_imports_the_lazy_modules_and_later_loads_at_once(monkeypatch):
    """Python's lazy modules are not thread-safe before 3.12.3: the drivers' threads must
    find every module estim registered lazily already imported."""
    import sys
    import types

    from estim.util import lazy

    monkeypatch.setattr(lazy, "_eager", False)
    monkeypatch.setattr(lazy, "_registered", [])
    for name in ("tabnanny", "netrc"):
        monkeypatch.delitem(sys.modules, name, raising=False)
    waiting = lazy.load("tabnanny")
    assert type(waiting) is not types.ModuleType              # not imported yet
    lazy.import_all_now()
    assert type(waiting) is types.ModuleType and callable(waiting.check)
    at_once = lazy.load("netrc")
    assert type(at_once) is types.ModuleType and "netrc" in vars(at_once)


def test_a_failing_config_stops_a_shared_run_without_hanging():
    """The first failure stops the pool; a driver whose units were still queued is woken
    (units cancelled instead of failed woke no waiter on Python 3.11: the run hung)."""
    import threading as th

    release = th.Event()

    def work(item: str):
        if item == "fails":
            release.wait(5)
            time.sleep(0.5)                     # the queued driver has submitted its units
            raise RuntimeError("boom")
        if item == "queued":
            release.set()
            return map_tasks(time.sleep, [0.3] * 20, jobs=1)
        return map_tasks(time.sleep, [0.3] * 8, jobs=1)

    outcome: list[str] = []

    def scenario() -> None:                 # in a thread: a hang fails the test, not CI
        try:
            with scheduler.process_pool(2) as pool:
                def driven(item):
                    with execution(pool=pool):
                        return work(item)
                list(scheduler.run_each(["long", "queued", "fails"], driven, threads=3,
                                        on_error=lambda: scheduler.stop(pool)))
        except RuntimeError as exc:
            outcome.append(str(exc))

    runner = th.Thread(target=scenario, daemon=True)
    runner.start()
    runner.join(60)
    assert outcome == ["boom"], "the run hung or did not raise the first failure"


@pytest.mark.slow
def test_reproduce_of_several_configs_prints_a_line_each_and_a_closing_summary(
        tmp_path, monkeypatch):
    """No tables in the stream: each finished config is one line (where it went, its time,
    its claims, k/N), then one summary with the verdict counts and what to run next."""
    root = fake_project(tmp_path, monkeypatch)
    (root / "configs" / "tiny2.yaml").write_text(yaml.safe_dump(
        tiny_config(name="tiny2", **{"monte_carlo.seed": 7})))
    out = CliRunner().invoke(main, ["reproduce", "--jobs", "2", "--out", str(tmp_path / "o")])
    assert out.exit_code == 0, out.output
    lines = out.output.splitlines()
    done = [line for line in lines if " -> " in line]
    assert len(done) == 2 and all(line.endswith(("[1/2]", "[2/2]")) for line in done)
    assert all("claims holds " in line for line in done)
    assert "noise_param" not in out.output                      # no table printed
    closing = next(line for line in lines if line.startswith("reproduce: 2 configs in "))
    assert "after Holm's correction" in closing
    assert any(line.startswith("Next: ") and "estim report" in line for line in lines)
    quiet = CliRunner().invoke(main, ["reproduce", "--jobs", "2", "--quiet", "--out",
                                      str(tmp_path / "q")])
    assert quiet.exit_code == 0 and quiet.output == ""
