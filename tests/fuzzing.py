"""Seeded mutation fuzzing of the files the command line reads (issue 22).

A case is a valid seed file of one format, a seeded mutation of its bytes and a ``brdf-fit``
command that reads it. :func:`run_case` runs the command in-process (``cli.main.main``) under a
time budget (SIGALRM) and a memory budget (RLIMIT_AS: the address space in use plus
:data:`MEMORY_BUDGET`), and returns what broke the promise of the README, or None: exit status
0, 1 or 2; on 2 exactly one stderr line, ``brdf-fit: error: ...``, naming the mutated file; no
traceback and no warning on any exit.
"""

import contextlib
import io
import json
import os
import random
import re
import resource
import signal
import struct
import time
import warnings
from pathlib import Path

import numpy as np

from tensor_files import small_material, tensor_file

#: Seconds of CPU one run may use (the slowest valid run, check of a MERL table, uses about
#: 3 s), and of wall-clock time (generous: the machine may be shared; a hang ends there).
CPU_BUDGET, TIME_BUDGET = 30.0, 120.0
#: Bytes of address space one run may add to the process.
MEMORY_BUDGET = 3 << 30
SPEC = "lambert(albedo=[0.5,0.4,0.3]) + ggx(alpha=0.3)"
RENDER = ["--spp", "1", "--size", "16x16"]
TEXT_FORMATS = {"csv", "alta", "json", "toml", "ies", "report"}


# --- seed files ----------------------------------------------------------------------------

def _scene(ies):
    return {"camera": {"origin": [0, 3, 3], "target": [0, 0, 0], "fov": 40},
            "materials": {"paint": {"brdf": "lambert(albedo=[0.6,0.5,0.4])"}},
            "shapes": [{"type": "quad", "corner": [-2, 0, 2], "edge1": [4, 0, 0],
                        "edge2": [0, 0, -4], "material": "@material"},
                       {"type": "sphere", "centre": [0, 0.5, 0], "radius": 0.5,
                        "material": "paint"}],
            "lights": [{"type": "point", "position": [0, 2, 0], "intensity": [2, 2, 2]},
                       {"type": "goniometric", "position": [1, 2, 0], "ies": ies}],
            "environment": {"radiance": 0.1}}


def _toml(doc):
    """``doc`` (tables of scalars, lists and tables) as TOML, tables inline."""
    def value(x):
        if isinstance(x, dict):
            return "{" + ", ".join(f"{k} = {value(v)}" for k, v in x.items()) + "}"
        if isinstance(x, list):
            return "[" + ", ".join(value(v) for v in x) + "]"
        return json.dumps(x)
    return "".join(f"{k} = {value(v)}\n" for k, v in doc.items())


def make_seeds(folder):
    """Write one valid file of each fuzzed format into ``folder``; ``{kind: path}``."""
    import brdf
    from brdf.io.merl import MerlTable
    folder = Path(folder)
    model = brdf.parse(SPEC)
    seeds = {}
    merl = folder / "seed.binary"
    brdf.write(MerlTable.from_table(model), merl)
    seeds["binary"] = merl
    csv = folder / "seed.csv"
    brdf.write(brdf.measure(model, "inplane:15", "relative:0.01", seed=1), csv)
    seeds["csv"] = csv
    npz = folder / "seed.npz"
    brdf.write(brdf.measure(model, "random:60", "relative:0.01", seed=2), npz)
    seeds["npz"] = npz
    alta = folder / "seed.alta"
    brdf.write(brdf.measure(model, "random:60", "relative:0.01", seed=3), alta)
    seeds["alta"] = alta
    bsdf = folder / "seed.bsdf"
    bsdf.write_bytes(tensor_file(small_material())[0])
    seeds["bsdf"] = bsdf
    ies = folder / "seed.ies"
    ies.write_text(IES)
    seeds["ies"] = ies
    # the scenes name the IES file by its absolute path: their mutants are written elsewhere
    (folder / "seed.json").write_text(json.dumps(_scene(str(ies)), indent=1))
    seeds["json"] = folder / "seed.json"
    (folder / "seed.toml").write_text(_toml(_scene(str(ies))))
    seeds["toml"] = folder / "seed.toml"
    from brdf_cli.main import main
    report = folder / "report.json"
    with contextlib.redirect_stdout(io.StringIO()):
        status = main(["fit", str(csv), "lambert + ggx(alpha=0.2)", "-o", str(report),
                       "--max-evals", "60", "-q"])
    assert status in (0, 1), status
    seeds["report"] = report
    return seeds


#: A small Type C LM-63 file: 5 vertical angles, 3 horizontal ones (0-180, bilateral).
IES = """IESNA:LM-63-2002
[TEST] fuzz seed
TILT=NONE
1 -1 1.0 5 3 1 2 0 0 0
1.0 1.0 10
0 22.5 45 67.5 90
0 90 180
100 90 70 40 10
100 80 60 30 5
100 85 65 35 8
"""


# --- commands --------------------------------------------------------------------------------

def commands(kind, path, out):
    """The ``brdf-fit`` argument lists that read ``path`` (a file of ``kind``); ``out`` is a
    folder for their outputs."""
    p = str(path)
    if kind in ("binary", "csv", "alta", "npz", "bsdf"):
        return [["info", p], ["check", p], ["convert", p, str(out / "out.npz"), "--force"],
                ["render", p, "-o", str(out / "out.exr"), "--force", *RENDER]]
    if kind == "report":
        return [["check", p], ["eval", p, "--wi", "30,0", "--wo", "40,180"],
                ["render", p, "-o", str(out / "out.exr"), "--force", *RENDER]]
    if kind in ("json", "toml"):
        return [["render", SPEC, "--scene", p, "-o", str(out / "out.exr"), "--force", *RENDER]]
    if kind == "ies":  # reached through the scene that names it
        scene = path.with_name(path.stem + ".scene.json")
        scene.write_text(json.dumps(_scene(path.name)))
        return [["render", SPEC, "--scene", str(scene), "-o", str(out / "out.exr"), "--force",
                 *RENDER]]
    raise ValueError(kind)


# --- mutations -------------------------------------------------------------------------------

NUMBERS = ["nan", "NaN", "inf", "-inf", "1e308", "-1e308", "1e999", "-1", "0", "-0", "1e-320",
           "1_000", "\uff10.\uff15", "\u0660.\u0665", "", "abc", "0x10", "99999999999999999999",
           "4294967296", "65535", "1,5", "+", "1e", "--1"]
ENCODINGS = ["utf-16", "utf-32", "latin-1", "cp1252", "utf-8-sig", "shift_jis"]
_NUMBER = re.compile(rb"-?\d+(\.\d+)?([eE][-+]?\d+)?")


def _truncate(rng, data, kind):
    return data[:rng.randrange(len(data))]


def _bit_flips(rng, data, kind):
    b = bytearray(data)
    for _ in range(rng.choice([1, 1, 2, 4, 16])):
        k = rng.randrange(len(b) * 8)
        b[k // 8] ^= 1 << (k % 8)
    return bytes(b)


def _insert(rng, data, kind):
    k = rng.randrange(len(data) + 1)
    junk = rng.choice([bytes(rng.randrange(256) for _ in range(rng.randrange(1, 17))),
                       b"\x00" * 8, b"\xff\xfe", b"\n", b",", b"[", b"{", b'"', b"\r\n\r\n"])
    return data[:k] + junk + data[k:]


def _delete(rng, data, kind):
    k = rng.randrange(len(data))
    return data[:k] + data[k + rng.randrange(1, 64):]


def _header(rng, data, kind):
    """An edit near the start: in text, a word of the first lines renamed, doubled or dropped;
    in binary, a byte of the first 64 set to 0, 0xff or a random value."""
    if kind in TEXT_FORMATS:
        lines = data.split(b"\n")
        n = min(len(lines), 8)
        i = rng.randrange(n)
        words = re.split(rb"([,\s=:\[\]{}]+)", lines[i])
        j = rng.randrange(len(words))
        words[j] = rng.choice([words[j] + b"_x", words[j] * 2, b"", words[j].upper(),
                               words[j][:-1]])
        lines[i] = b"".join(words)
        return b"\n".join(lines)
    b = bytearray(data)
    b[rng.randrange(min(64, len(b)))] = rng.choice([0, 0xFF, rng.randrange(256)])
    return bytes(b)


def _number(rng, data, kind):
    """A number replaced: in text a token by one of :data:`NUMBERS`; in binary 8 or 4 aligned
    bytes by a NaN, an infinity, a huge value or a huge count."""
    if kind in TEXT_FORMATS:
        spans = [m.span() for m in _NUMBER.finditer(data)]
        if not spans:
            return _insert(rng, data, kind)
        a, b = rng.choice(spans)
        return data[:a] + rng.choice(NUMBERS).encode() + data[b:]
    width = rng.choice([4, 8])
    k = rng.randrange(len(data) // width) * width
    value = rng.choice([struct.pack("<d", x) for x in (np.nan, np.inf, -np.inf, 1e308, -1.0)]
                       if width == 8 else
                       [struct.pack("<f", x) for x in (np.nan, np.inf, -1.0, 3e38)]
                       + [struct.pack("<I", x) for x in (0, 65535, 2**31, 2**32 - 1)])
    return data[:k] + value + data[k + width:]


def _encoding(rng, data, kind):
    """Text in another encoding (with a non-ASCII character, so that it differs); binary
    formats get a UTF-8 BOM or a text preamble."""
    if kind in TEXT_FORMATS:
        text = data.decode("utf-8", "replace")
        k = rng.randrange(len(text) + 1)
        text = text[:k] + rng.choice(["é", "µ", "日本", "\u2028", "\x00"]) + text[k:]
        return text.encode(rng.choice(ENCODINGS), "replace")
    return rng.choice([b"\xef\xbb\xbf", b"# comment\n"]) + data


def _nesting(rng, data, kind):
    """Deep nesting for JSON and TOML (a value nested thousands of levels), repeated lines for
    the other text formats, a repeated block for binary ones."""
    depth = rng.choice([1000, 100_000])
    if kind in ("json", "report"):
        return data.rstrip()[:-1] + b', "deep": ' + b"[" * depth + b"]" * depth + b"}"
    if kind == "toml":
        return data + b"deep = " + b"[" * depth + b"]" * depth + b"\n"
    lines = data.split(b"\n")
    i = rng.randrange(len(lines))
    if kind in TEXT_FORMATS:
        return b"\n".join(lines[:i] + [lines[i]] * rng.randrange(2, 50) + lines[i:])
    k = rng.randrange(len(data))
    return data[:k] + data[k:k + 64] * rng.randrange(2, 20) + data[k:]


MUTATIONS = {"truncate": _truncate, "bit-flips": _bit_flips, "insert": _insert,
             "delete": _delete, "header": _header, "number": _number, "encoding": _encoding,
             "nesting": _nesting}


def mutate(seed, data, kind):
    """``(mutation name, mutated bytes)`` for case ``seed`` (the same bytes for the same seed)."""
    rng = random.Random(seed)
    name = rng.choice(sorted(MUTATIONS))
    return name, MUTATIONS[name](rng, data, kind)


# --- special files ---------------------------------------------------------------------------

def special_files(folder):
    """``(description, path)`` of non-regular inputs: a FIFO, /dev/zero and /dev/urandom
    behind each format's extension, a folder and an empty file."""
    folder = Path(folder)
    out = []
    for ext in ("binary", "bsdf", "npz", "csv", "json", "toml", "ies"):
        fifo = folder / f"fifo.{ext}"
        os.mkfifo(fifo)
        out.append((f"FIFO .{ext}", ext, fifo))
        zero = folder / f"zero.{ext}"
        zero.symlink_to("/dev/zero")
        out.append((f"/dev/zero .{ext}", ext, zero))
        empty = folder / f"empty.{ext}"
        empty.write_bytes(b"")
        out.append((f"empty .{ext}", ext, empty))
        d = folder / f"folder.{ext}"
        d.mkdir()
        out.append((f"folder .{ext}", ext, d))
    return out


# --- running ---------------------------------------------------------------------------------

class Overtime(BaseException):
    """A run took longer than its time budget (a BaseException: the command line's handler
    of every Exception must not turn it into an exit status)."""


def _alarm(signum, frame):
    raise Overtime()


def _address_space():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[0]) * resource.getpagesize()


@contextlib.contextmanager
def budget(seconds=TIME_BUDGET, memory=MEMORY_BUDGET):
    """Raise :class:`Overtime` after ``seconds``; allow ``memory`` more bytes of address space."""
    old_handler = signal.signal(signal.SIGALRM, _alarm)
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    resource.setrlimit(resource.RLIMIT_AS, (_address_space() + memory, hard))
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old_handler)
        resource.setrlimit(resource.RLIMIT_AS, (soft, hard))


def run_cli(argv, seconds=TIME_BUDGET):
    """``(status, stderr, warnings)`` of ``brdf-fit argv`` run in-process; status is
    ``"overtime"``, ``"memory"`` or ``"over the CPU budget"`` when a budget ran out."""
    from brdf_cli.main import main
    err = io.StringIO()
    cpu = time.process_time()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("default")
        warnings.simplefilter("ignore", DeprecationWarning)
        warnings.simplefilter("ignore", PendingDeprecationWarning)
        try:
            with budget(seconds), contextlib.redirect_stderr(err), \
                    contextlib.redirect_stdout(io.StringIO()):
                status = main(argv)
        except Overtime:
            status = "overtime"
        except MemoryError:
            status = "memory"
    if time.process_time() - cpu > CPU_BUDGET:
        status = f"over the CPU budget ({time.process_time() - cpu:.0f} s)"
    return status, err.getvalue(), [f"{w.category.__name__}: {w.message}" for w in caught]


#: A line long work prints on stderr off a terminal (brdf.progress: ``brdf-fit: fit: 853
#: evals in 2.1 s``, ``brdf-fit: batch: t1.csv fitted (2 of 3) after 4.1 s``); such lines come
#: before any error and are not part of it.
PROGRESS_LINE = re.compile(r"brdf(-fit)?: (fit|mcmc|render|batch|demo|export): .* (in|after) "
                           r"\d+(\.\d+)? s$")


def without_progress(err):
    """``err`` less its progress lines (:data:`PROGRESS_LINE`)."""
    return "".join(line for line in err.splitlines(keepends=True)
                   if not PROGRESS_LINE.match(line.rstrip("\n")))


def verdict(status, stderr, caught, path):
    """What broke the promise (a short text), or None. Progress lines of work that finished
    before the error may precede its one line."""
    if status not in (0, 1, 2):
        return f"status {status}: {stderr.strip()[-300:]}"
    if "Traceback" in stderr:
        return "traceback"
    if caught:
        return f"warning: {caught[0][:200]}"
    if status == 2:
        lines = without_progress(stderr).splitlines()
        if len(lines) != 1 or not lines[0].startswith("brdf-fit: error: "):
            return f"{len(lines)} stderr lines: {stderr.strip()[:300]}"
        if Path(path).name not in lines[0]:
            return f"does not name {Path(path).name}: {lines[0][:300]}"
    return None


def fuzz_case(seeds, kind, seed, folder):
    """Mutate ``seeds[kind]`` with ``seed``, run one of its commands; ``(label, problem)``."""
    data = Path(seeds[kind]).read_bytes()
    name, mutated = mutate(seed, data, kind)
    path = Path(folder) / f"m{seed}{Path(seeds[kind]).suffix}"
    if kind == "ies":
        path = Path(folder) / f"m{seed}.ies"
    path.write_bytes(mutated)
    argvs = commands(kind, path, Path(folder))
    argv = argvs[random.Random(seed + 1).randrange(len(argvs))]
    status, stderr, caught = run_cli(argv)
    problem = verdict(status, stderr, caught, path)
    label = f"{kind} {name} seed={seed}: brdf-fit {' '.join(argv[:1])}"
    return label, problem, path
