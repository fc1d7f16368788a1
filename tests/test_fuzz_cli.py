"""Hostile input to ``brdf-fit`` (issue 22): seeded mutations of a valid file of every format,
special files, odd arguments, requests too large for memory, signals and stale temporary
files. Every run must end with exit status 0, 1 or 2, and on 2 with exactly one stderr line
``brdf-fit: error: ...`` naming the file or option; never a traceback, a warning, a hang or a
runaway allocation (see tests/fuzzing.py for the budgets)."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

import fuzzing

#: Mutants per format in CI (about 120 runs in a minute: a MERL table's check takes seconds,
#: so its format gets fewer), and per format in the slow run.
CASES = {"binary": 6}
DEFAULT_CASES, SLOW_CASES = 16, 80


@pytest.fixture(scope="module")
def seeded(tmp_path_factory):
    """The seed files, and each of their commands run once without a time budget (on a cold
    numba cache the first runs compile kernels for minutes)."""
    seeds = fuzzing.make_seeds(tmp_path_factory.mktemp("seeds"))
    out = tmp_path_factory.mktemp("seed-runs")
    runs = [(argv, *fuzzing.run_cli(argv, seconds=1800))
            for kind, path in seeds.items() for argv in fuzzing.commands(kind, Path(path), out)]
    return seeds, runs


@pytest.fixture(scope="module")
def seeds(seeded):
    return seeded[0]


def _fuzz(seeds, kind, count, tmp_path):
    broken = []
    for seed in range(count):
        folder = tmp_path / f"{kind}-{seed}"
        folder.mkdir()
        label, problem, _ = fuzzing.fuzz_case(seeds, kind, seed, folder)
        if problem:
            broken.append(f"{label}: {problem}")
    assert not broken, f"{len(broken)} of {count} runs broke the promise:\n" + "\n".join(broken)


KINDS = ["binary", "csv", "alta", "npz", "bsdf", "json", "toml", "report", "ies"]


#: the tests of the seed files share a worker (README's test command uses --dist loadgroup):
#: each worker would otherwise run the seeds' commands again, 20 s each time on a slow host
SEEDS = pytest.mark.xdist_group("fuzz-seeds")


@SEEDS
@pytest.mark.parametrize("kind", KINDS)
def test_mutated_files_get_one_line_and_status(seeds, kind, tmp_path):
    _fuzz(seeds, kind, CASES.get(kind, DEFAULT_CASES), tmp_path)


@SEEDS
@pytest.mark.slow
@pytest.mark.parametrize("kind", KINDS)
def test_mutated_files_many(seeds, kind, tmp_path):
    _fuzz(seeds, kind, SLOW_CASES, tmp_path)


@SEEDS
def test_the_seeds_are_valid(seeded):
    """Unmutated, every command reads its seed and succeeds (or fails a check): the mutants'
    refusals are theirs."""
    for argv, status, err, caught in seeded[1]:
        assert status in (0, 1) and not caught, (argv, status, err, caught)


def test_special_files_are_refused_without_reading(tmp_path):
    """A FIFO would block open() forever, /dev/zero would be read without end; a folder or an
    empty file is refused too. Each gets its one line, within 5 s."""
    broken = []
    for description, kind, path in fuzzing.special_files(tmp_path):
        for argv in fuzzing.commands(kind, path, tmp_path):
            t0 = time.monotonic()
            status, err, caught = fuzzing.run_cli(argv, seconds=5)
            problem = fuzzing.verdict(status, err, caught, path)
            if status != 2:
                problem = problem or f"status {status}"
            if problem or time.monotonic() - t0 > 5:
                broken.append(f"{description} {argv[0]}: {problem}")
    assert not broken, "\n".join(broken)


# --- arguments ---------------------------------------------------------------------------------

SPEC = "lambert(albedo=0.5)"
#: Bad values of every numeric option, and the fragment the one-line error must hold.
BAD_ARGUMENTS = [
    (["demo", "--seed", "-1"], "--seed"),
    (["check", SPEC, "--seed", "1.5"], "--seed"),
    (["check", SPEC, "--seed", "\uff11"], "--seed"),  # a full-width digit
    (["render", SPEC, "-o", "o.png", "--exposure", "1e308"], "--exposure"),
    (["render", SPEC, "-o", "o.png", "--exposure", "nan"], "--exposure"),
    (["render", SPEC, "-o", "o.png", "--exposure", "inf"], "--exposure"),
    (["render", SPEC, "-o", "out.txt"], "--output"),
    (["render", SPEC, "-o", "o.exr", "--preview", "p.exr"], "--preview"),
    (["render", SPEC, "-o", "o.exr", "--threads", "0"], "--threads"),
    (["render", SPEC, "-o", "o.exr", "--threads", "-1"], "--threads"),
    (["render", SPEC, "-o", "o.exr", "--spp", "0"], "--spp"),
    (["render", SPEC, "-o", "o.exr", "--spp", "1_000"], "--spp"),
    (["render", SPEC, "-o", "o.exr", "--max-depth", "0"], "--max-depth"),
    (["render", SPEC, "-o", "o.exr", "--size", "0x4"], "--size"),
    (["render", SPEC, "-o", "o.exr", "--size", "\u0664x4"], "--size"),  # Arabic-Indic 4
    (["lobe", SPEC, "--resolution", "-3"], "--resolution"),
    (["lobe", SPEC, "--resolution", "100000"], "--resolution"),
    (["lobe", SPEC, "--theta-i", "90"], "--theta-i"),
    (["lobe", SPEC, "--channel", "-1"], "--channel"),
    (["plot", "albedo", SPEC, "-o", "a.png", "--channel", "-1"], "--channel"),
    (["plot", "residuals", SPEC, "-o", "a.png", "--cutoff", "0"], "--cutoff"),
    (["plot", "predictive", "d.csv", SPEC, "-o", "a.png", "--draws", "0"], "--draws"),
    (["fit", "d.csv", SPEC, "--starts", "0"], "--starts"),
    (["fit", "d.csv", SPEC, "--cutoff", "nan"], "--cutoff"),
    (["fit", "d.csv", SPEC, "--cutoff", "95"], "--cutoff"),
    (["fit", "d.csv", SPEC, "--max-evals", "-5"], "--max-evals"),
    (["fit", "d.csv", SPEC, "--mcmc", "--walkers", "1"], "--walkers"),
    (["fit", "d.csv", SPEC, "--mcmc", "--max-steps", "0"], "--max-steps"),
    (["fit", "d.csv", SPEC, "--mcmc", "--corner", "c.pdf"], "--corner"),
    (["batch", "*.csv", SPEC, "-o", "out", "--jobs", "0"], "--jobs"),
    (["info", "x.dat", "--sample", "0"], "--sample"),
    (["eval", SPEC, "--wi", "30,nan", "--wo", "0,0"], "--wi"),
    (["albedo", SPEC, "--theta-i", "91"], "--theta-i"),
]


@pytest.mark.parametrize("argv, option", BAD_ARGUMENTS, ids=lambda x: " ".join(x)
                         if isinstance(x, list) else x)
def test_bad_arguments_are_refused_by_name(argv, option, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    status, err, caught = fuzzing.run_cli(argv)
    assert status == 2, (status, err)
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("brdf-fit: error: "), err
    assert option in lines[0], lines[0]
    assert not caught and not list(tmp_path.iterdir())


def _one_line(err, *fragments):
    lines = fuzzing.without_progress(err).splitlines()  # a finished render's line may precede
    assert len(lines) == 1 and lines[0].startswith("brdf-fit: error: "), err
    for fragment in fragments:
        assert fragment in lines[0], lines[0]
    return lines[0]


def test_library_arguments_from_the_command_line(tmp_path, monkeypatch):
    """Strings the library parses (geometry, noise, --fix) are checked as strictly."""
    monkeypatch.chdir(tmp_path)
    for argv, fragment in [
            (["synth", SPEC, "--geometry", "random:\uff11\uff10", "-o", "s.csv"], "random:"),
            (["synth", SPEC, "--geometry", "inplane:1_0", "-o", "s.csv"], "inplane:"),
            (["synth", SPEC, "--noise", "additive:1e308", "-o", "s.csv"], "overflow"),
            (["fit", str(Path(__file__).parent / "data" / "gonio_rgb.csv"), SPEC, "--fix",
              "lambert.albedo=nan"], "--fix")]:
        status, err, caught = fuzzing.run_cli(argv)
        assert status == 2 and not caught, (argv, err)
        _one_line(err, fragment)
    assert not list(tmp_path.iterdir())


# --- memory ------------------------------------------------------------------------------------

@pytest.mark.parametrize("argv, fragment", [
    (["render", SPEC, "-o", "big.exr", "--size", "16384x16384", "--spp", "1"], "16384 x 16384"),
    (["synth", SPEC, "--geometry", "random:1000000000000", "-o", "s.csv"], "random:"),
    (["synth", SPEC, "--geometry", "grid:0.01,0.01", "-o", "s.csv"], "grid:0.01,0.01"),
    (["synth", SPEC, "--geometry", "inplane:0.0001", "-o", "s.csv"], "inplane:0.0001"),
    (["lobe", SPEC, "--theta-i", "10,30,50,70", "--resolution", "1024", "-o", "l.png"],
     "4 lobes at resolution 1024"),
])
def test_requests_larger_than_memory_are_refused_before_allocating(argv, fragment, tmp_path,
                                                                    monkeypatch):
    """The estimate is compared with the memory available (capped here at 2 GB more than the
    process holds, so the test means the same on any machine): the refusal says how much the
    request needs, and comes before any allocation (the budget would stop one)."""
    monkeypatch.chdir(tmp_path)
    import brdf.memory
    monkeypatch.setattr(brdf.memory, "_meminfo_available", lambda: 2 << 30)
    t0 = time.monotonic()
    status, err, caught = fuzzing.run_cli(argv, seconds=20)
    assert status == 2 and not caught, (status, err)
    line = _one_line(err, fragment, "needs about", "available")
    assert " GB" in line or " TB" in line
    assert time.monotonic() - t0 < 20 and not list(tmp_path.iterdir())


def test_memory_estimate_admits_what_fits(tmp_path, monkeypatch):
    """The same check lets through what fits: an estimate too high would refuse work."""
    import brdf
    import brdf.memory
    from brdf.render import PIXEL_BYTES
    from brdf.gonioreflectometer import SAMPLE_BYTES
    monkeypatch.setattr(brdf.memory, "_meminfo_available", lambda: 64 << 20)
    assert 64 * 64 * PIXEL_BYTES < 64 << 20
    brdf.render.render(brdf.render.builtin("sphere", SPEC), spp=1, size=(64, 64))
    assert 20000 * (SAMPLE_BYTES + 96) < 64 << 20
    assert len(brdf.measure(SPEC, "random:20000")) == 20000


# --- signals and stale temporary files ---------------------------------------------------------

def _cli(*argv):
    return subprocess.Popen([sys.executable, "-c", "import sys; from brdf_cli.main import main; "
                             "sys.exit(main())", *argv],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def test_sigterm_while_writing_removes_the_partial_output(tmp_path, monkeypatch):
    """SIGTERM arriving while an output is half written: the temporary file is removed, the
    target never appears, the status is 128 + 15 (main(), in this test's main thread)."""
    from PIL import Image

    def save_then_terminated(self, fp, *args, **kwargs):
        Path(fp).write_bytes(b"\x89PNG partial")
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(5)  # the handler raises here, in the main thread
        raise AssertionError("SIGTERM was not handled")

    monkeypatch.setattr(Image.Image, "save", save_then_terminated)
    before = signal.getsignal(signal.SIGTERM)
    out = tmp_path / "out.png"
    status, err, _ = fuzzing.run_cli(["render", SPEC, "-o", str(out), *fuzzing.RENDER])
    assert status == 143, err
    _one_line(err, "SIGTERM")
    assert not list(tmp_path.iterdir())
    assert signal.getsignal(signal.SIGTERM) is before  # restored after the run


def test_sigterm_while_rendering_exits_143(tmp_path):
    """A real process: SIGTERM during a long render ends it with status 143 and one line,
    leaving nothing beside the target."""
    out = tmp_path / "big.exr"
    # the threads a process has once numpy is in (its BLAS may start some)
    before = int(subprocess.run([sys.executable, "-c", "import os, numpy; "
                                 "print(len(os.listdir('/proc/self/task')))"],
                                capture_output=True, text=True, check=True).stdout)
    p = _cli("render", SPEC, "-o", str(out), "--size", "512x512", "--spp", "100000",
             "--threads", "2", "--scene", "furnace")
    deadline = time.monotonic() + 180
    # the render's second thread starts with the render: then the handler is in place
    while p.poll() is None and time.monotonic() < deadline:
        if len(os.listdir(f"/proc/{p.pid}/task")) > before:
            break
        time.sleep(0.1)
    assert p.poll() is None and time.monotonic() < deadline, "the render never started"
    time.sleep(1.0)
    p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=120)
    assert p.returncode == 143, err
    _one_line(err, "SIGTERM")
    assert not list(tmp_path.iterdir())


def test_stale_temporary_files_of_dead_processes_are_removed(tmp_path):
    """SIGKILL cannot be handled: the next write of the same target removes what a killed
    writer left (its PID is in the name); a live writer's file and other targets' stay."""
    from brdf.io.files import atomic_output
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True).stdout.strip()
    stale = tmp_path / f".out.{dead}.abcd_123.csv"
    live = tmp_path / f".out.{os.getppid()}.abcd_123.csv"
    other = tmp_path / f".other.{dead}.abcd_123.csv"
    for p in (stale, live, other):
        p.write_text("partial")
    with atomic_output(tmp_path / "out.csv") as tmp:
        tmp.write_text("done")
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        ["out.csv", live.name, other.name])
    assert (tmp_path / "out.csv").read_text() == "done"


def test_sigkill_leftover_is_removed_by_the_next_run(tmp_path):
    """A writer killed (SIGKILL) inside its atomic write leaves its temporary file; the next
    brdf-fit run that writes the same target removes it."""
    out = tmp_path / "big.exr"
    killed = subprocess.run([sys.executable, "-c", f"""
import os, signal
from brdf.io.files import atomic_output
with atomic_output({str(out)!r}) as tmp:
    tmp.write_bytes(b"partial")
    os.kill(os.getpid(), signal.SIGKILL)
"""])
    assert killed.returncode == -signal.SIGKILL
    (leftover,) = tmp_path.iterdir()
    assert leftover.name.startswith(".big.") and leftover.suffix == ".exr"
    p = _cli("render", SPEC, "-o", str(out), *fuzzing.RENDER)
    _, err = p.communicate(timeout=300)
    assert p.returncode == 0, err
    assert [n.name for n in tmp_path.iterdir()] == ["big.exr"]


@SEEDS
def test_convert_onto_a_folder_names_the_folder(seeds, tmp_path):
    target = tmp_path / "adir.npz"
    target.mkdir()
    status, err, _ = fuzzing.run_cli(["convert", str(seeds["csv"]), str(target), "--force"])
    assert status == 2
    line = _one_line(err, str(target), "folder")
    assert ".adir." not in line and list(target.parent.iterdir()) == [target]


def test_synth_refuses_spectral_as_merl_rgb(tmp_path):
    data = Path(__file__).parent / "data" / "gonio_spectral.csv"
    out = tmp_path / "s.binary"
    status, err, _ = fuzzing.run_cli(["synth", str(data), "--geometry", "merl", "-o", str(out)])
    assert status == 2 and not out.exists()
    convert_status, convert_err, _ = fuzzing.run_cli(["convert", str(data), str(out)])
    assert convert_status == 2
    # the same refusal as convert's
    assert _one_line(err, "MERL stores RGB", "spectral") == _one_line(convert_err)
