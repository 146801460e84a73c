"""A Ctrl-C that arrives during a garbage-collection callback still interrupts the command."""
import gc
import os
import signal
import sys
import time

import pytest

from softshadow_cli.interrupts import ctrl_c_never_swallowed


@pytest.fixture
def python_sigint():
    # The test runner may have SIGINT ignored (inherited); give Python's default handler for the test.
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


def _ctrl_c_during_gc_callback(wait_s: float) -> None:
    def callback(phase, info):
        if phase == "start":
            os.kill(os.getpid(), signal.SIGINT)
            sum(range(10_000))  # bytecodes inside the callback: the handler runs here

    gc.callbacks.append(callback)
    try:
        gc.collect()
    finally:
        gc.callbacks.remove(callback)
    deadline = time.monotonic() + wait_s
    while time.monotonic() < deadline:
        time.sleep(0.01)


def test_plain_python_swallows_it(python_sigint, monkeypatch):
    # The failure this module exists for: Python ignores the KeyboardInterrupt (prints
    # "Exception ignored in: gc callback") and goes on.
    ignored = []
    monkeypatch.setattr(sys, "unraisablehook", lambda u: ignored.append(u.exc_type))
    _ctrl_c_during_gc_callback(0.5)
    assert ignored == [KeyboardInterrupt]


def test_ctrl_c_in_gc_callback_is_delivered(python_sigint):
    # Swallowed, the interrupt would let the 30 s wait run out; the bound leaves room for a full
    # collection of a large heap on a loaded machine (3.5 s seen at load 15).
    started = time.monotonic()
    with pytest.raises(KeyboardInterrupt):
        with ctrl_c_never_swallowed():
            _ctrl_c_during_gc_callback(30.0)
    assert time.monotonic() - started < 15.0
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_ordinary_ctrl_c_raises_at_once(python_sigint):
    with pytest.raises(KeyboardInterrupt):
        with ctrl_c_never_swallowed():
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(5.0)


def test_ignored_sigint_stays_ignored():
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        with ctrl_c_never_swallowed():
            assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, previous)


def test_a_press_in_an_earlier_block_is_not_the_next_ones(python_sigint):
    """A Ctrl-C an earlier command of the same process saw is forgotten by the next block, also
    when that block leaves SIGINT alone (ignored, or set by the caller)."""
    from softshadow_cli.interrupts import ctrl_c_pressed
    with pytest.raises(KeyboardInterrupt):
        with ctrl_c_never_swallowed():
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(5.0)
    assert ctrl_c_pressed()
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        with ctrl_c_never_swallowed():
            assert not ctrl_c_pressed()
    finally:
        signal.signal(signal.SIGINT, previous)


def test_ctrl_c_in_a_ctypes_callback_is_delivered_not_printed(python_sigint, monkeypatch):
    """numba's compilation cache calls Python through llvmlite's ctypes callbacks: a Ctrl-C landing
    there was printed as "Exception ignored on calling ctypes callback function" and the command
    went on. It is delivered again instead, and nothing is printed."""
    import ctypes
    printed = []
    monkeypatch.setattr(sys, "unraisablehook", lambda u: printed.append(u.exc_type))

    @ctypes.CFUNCTYPE(ctypes.c_int)
    def callback():
        os.kill(os.getpid(), signal.SIGINT)
        sum(range(100_000))  # bytecodes inside the callback: the handler runs here
        return 0

    started = time.monotonic()
    with pytest.raises(KeyboardInterrupt):
        with ctrl_c_never_swallowed():
            callback()
            time.sleep(30.0)
    assert time.monotonic() - started < 15.0 and printed == []
    assert sys.unraisablehook is not None and signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_ctrl_c_swallowed_by_a_bare_except_is_delivered_again(python_sigint):
    started = time.monotonic()
    with pytest.raises(KeyboardInterrupt):
        with ctrl_c_never_swallowed():
            try:
                os.kill(os.getpid(), signal.SIGINT)
                time.sleep(5.0)
            except:  # noqa: E722 - what some libraries do
                pass
            time.sleep(30.0)
    assert time.monotonic() - started < 15.0


def test_ctrl_c_inside_an_extension_module_import_waits_for_it(python_sigint, monkeypatch):
    """Inside a C++ extension module's initialisation (jaxlib's), a KeyboardInterrupt crossing the
    C++ code aborted the process ("terminate called ... nanobind::python_error") or crashed it.
    There the handler waits: the initialisation finishes, then the Ctrl-C is raised."""
    import softshadow_cli.interrupts as interrupts

    def extension_init():  # stands for ExtensionFileLoader.exec_module
        os.kill(os.getpid(), signal.SIGINT)
        sum(range(100_000))
        time.sleep(0.3)  # still inside: the handler is called again and waits again
        return "initialised"

    monkeypatch.setattr(interrupts, "_NATIVE_IMPORT", frozenset({extension_init.__code__}))
    finished = []
    started = time.monotonic()
    with pytest.raises(KeyboardInterrupt):
        with ctrl_c_never_swallowed():
            finished.append(extension_init())
            time.sleep(30.0)  # a blocking wait after it: the Ctrl-C still ends it
    assert finished == ["initialised"] and time.monotonic() - started < 15.0


def test_exit_status_is_130_after_a_ctrl_c_inside_exec(tmp_path):
    """A KeyboardInterrupt that leaves code run by exec of a string (dataclasses are made so) made
    CPython end by killing itself with SIGINT (status -2) although the command caught it and
    exited with 130."""
    import subprocess
    from pathlib import Path
    script = tmp_path / "run.py"
    script.write_text(
        "import os, signal, sys\n"
        "signal.signal(signal.SIGINT, signal.default_int_handler)\n"
        "from softshadow_cli.interrupts import ctrl_c_never_swallowed\n"
        "try:\n"
        "    with ctrl_c_never_swallowed():\n"
        "        exec('import os, signal\\nos.kill(os.getpid(), signal.SIGINT)\\nsum(range(10 ** 5))')\n"
        "except KeyboardInterrupt:\n"
        "    print('caught', file=sys.stderr)\n"
        "    sys.exit(130)\n")
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1]))
    proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, env=env, timeout=120)
    assert proc.returncode == 130 and proc.stderr.strip() == "caught", (proc.returncode, proc.stderr)


# --------------------------------------------------------------------------- a real fit, interrupted while compiling

_COMPILE_DRIVER = """
import signal, sys
signal.signal(signal.SIGINT, signal.default_int_handler)  # as a shell starts it
import jax._src.compiler as xla
import numba.core.dispatcher as numba_dispatch

seen = set()
def marked(tag, fn):
    def compiling(*args, **kwargs):
        if tag not in seen:
            seen.add(tag)
            print(f"test: compiling {tag}", file=sys.stderr, flush=True)
        return fn(*args, **kwargs)
    return compiling
numba_dispatch.Dispatcher.compile = marked("numba", numba_dispatch.Dispatcher.compile)
xla.backend_compile_and_load = marked("xla", xla.backend_compile_and_load)
from softshadow_cli.main import run
run(sys.argv[1:])
"""


@pytest.fixture(scope="module")
def pillar_folder(tmp_path_factory):
    from data_synth import synthesize
    return synthesize(tmp_path_factory.mktemp("compile") / "pillar", preset="pillar", seed=0, renderer="model",
                      size=(200, 150), progress=False)


@pytest.mark.parametrize("compiler, delay_s", [("numba", 0.0), ("numba", 0.3), ("xla", 0.0), ("xla", 0.5)])
def test_ctrl_c_while_compiling_is_one_line_and_130(pillar_folder, tmp_path, compiler, delay_s):
    """SIGINT sent while numba (through llvmlite) or XLA compiles, in a fresh process with empty
    compilation caches: one line, exit status 130, no traceback, whenever it lands."""
    import subprocess
    import threading
    from pathlib import Path
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1]),
               NUMBA_CACHE_DIR=str(tmp_path / "numba"), SOFTSHADOW_JAX_CACHE=str(tmp_path / "jax"))
    cmd = [sys.executable, "-c", _COMPILE_DRIVER, "fit", str(pillar_folder), "--out", str(tmp_path / "out"),
           "--no-plots"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
    err = bytearray()
    reader = threading.Thread(target=lambda: [err.extend(c) for c in iter(lambda: proc.stderr.read1(4096), b"")],
                              daemon=True)
    reader.start()
    marker = f"test: compiling {compiler}".encode()
    deadline = time.monotonic() + 300
    while marker not in err and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.01)
    assert marker in err, err.decode(errors="replace")
    time.sleep(delay_s)
    proc.send_signal(signal.SIGINT)
    sent = time.monotonic()
    proc.wait(timeout=120)
    reader.join(timeout=10)
    text = err.decode(errors="replace")
    assert proc.returncode == 130, text
    assert "Traceback" not in text and "Exception ignored" not in text and "KeyboardInterrupt" not in text, text
    lines = [ln for ln in text.replace("\r", "\n").splitlines()
             if ln.strip() and not ln.startswith(("test: ", "fitting:"))]
    assert len(lines) == 1 and lines[0].startswith("softshadow fit: interrupted"), text
    assert time.monotonic() - sent < 60


def test_after_a_ctrl_c_the_half_built_objects_say_nothing(tmp_path):
    """An object the Ctrl-C left half-built (llvmlite's, during numba's compilation) fails in its
    __del__ as the command ends: "Exception ignored in ... __del__" with a traceback, after the one
    line. The command, interrupted, drops those."""
    import subprocess
    from pathlib import Path
    script = tmp_path / "run.py"
    script.write_text(
        "import signal, sys\n"
        "signal.signal(signal.SIGINT, signal.default_int_handler)\n"
        "import importlib\n"
        "cli = importlib.import_module('softshadow_cli.main')\n"
        "class HalfBuilt:\n"
        "    def __del__(self):\n"
        "        self.never_set\n"
        "def command(args):\n"
        "    global kept\n"
        "    kept = HalfBuilt()\n"
        "    raise KeyboardInterrupt\n"
        "cli._add_demo = lambda sub: sub.add_parser('demo').set_defaults(func=command)\n"
        "cli._use_compilation_cache = lambda: None\n"
        "cli._option_problem = lambda args: None\n"
        "code = cli.main(['demo'])\n"
        "del kept\n"
        "sys.exit(code)\n")
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1]))
    proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, env=env, timeout=120)
    assert proc.returncode == 130 and proc.stderr.strip() == "softshadow demo: interrupted", proc.stderr
