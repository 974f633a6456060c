"""A fork server for the suite's ``python -m cosim`` commands: each command still runs in a process of its own, forked
from an interpreter that has already imported what every command imports, instead of a new interpreter importing it
again (about 0.5 s of CPU a command on the project's 2-core machine: numpy, fmpy, pydantic and the scenario schema,
for each of the suite's several hundred commands).

What the command sees is what ``python -m cosim ARGS`` started by :func:`subprocess.run` sees: ``cosim/__main__.py``
executed as ``__main__`` (:func:`runpy.run_module`), ``sys.argv``, the environment, the working folder, standard input
from /dev/null, standard output and error on pipes the caller reads to their end (a process the command leaves
behind holding them is waited for, as with :mod:`subprocess`), the exit status (a signal's included), and a timeout
that kills it (``sys.orig_argv`` too is set as a new interpreter's would be). What differs is only what an
interpreter decides when it starts: the locale and the standard streams' encoding, UTF-8 mode, ``sys.flags``, the
modules already loaded. :func:`cli_helpers.cosim` therefore sends a command
here only when its environment changes none of the variables read at start-up (:data:`STARTUP_VARIABLES`) and no
``preexec_fn`` or other :mod:`subprocess` option is given; every other command, and every test of start-up itself
(``--help``'s imports, locale, signals, lazy imports), runs a new interpreter as before.

Protocol (one server per pytest worker, one command at a time, over a Unix socket pair): the client sends a JSON
request with the command's stdout and stderr pipe ends as SCM_RIGHTS; the server forks, answers the child's pid, then
its wait status once it ended.
"""

from __future__ import annotations

import json
import os
import socket
import struct
import sys

STARTUP_VARIABLES = ("LANG", "LANGUAGE", "LC_", "PYTHON", "OPENBLAS", "OMP_", "MKL_")
"""Prefixes of environment variables an interpreter or a library reads when it starts or loads: a command whose
environment sets or changes one of them runs a new interpreter."""

PRELOAD = ("numpy", "fmpy", "fmpy.fmi2", "fmpy.fmi3", "pydantic", "yaml", "lxml.etree", "cosim.cli", "cosim.run",
           "cosim.engine.schema", "cosim.engine.overrides", "cosim.robot.preflight", "cosim.io.ssp.read",
           "cosim.io.ssp.write", "cosim.io.runlog", "delta.trajectories", "fmus.registry", "mcap.reader")
"""What the server imports once (a module not listed is imported by the command itself, as in a new interpreter; a
listed one that no longer exists stops the server)."""

_MAX = 1 << 20  # bytes of one request


def _serve(sock: socket.socket) -> None:
    import importlib
    import runpy
    import tempfile

    for name in PRELOAD:  # a name gone stale ends the server, and the suite's first command says so
        importlib.import_module(name)
    sys.stdout.flush()
    sys.stderr.flush()
    while True:
        try:
            data, fds, _, _ = socket.recv_fds(sock, _MAX, 2)
        except OSError:
            return
        if not data:  # the worker ended
            return
        request = json.loads(data)
        pid = os.fork()
        if pid == 0:
            status = 70
            try:
                sock.close()
                null = os.open(os.devnull, os.O_RDONLY)
                os.dup2(null, 0)
                os.dup2(fds[0], 1)
                os.dup2(fds[1], 2)
                for fd in (null, *fds):
                    os.close(fd)
                os.chdir(request["cwd"])
                os.environ.clear()
                os.environ.update(request["env"])
                tempfile.tempdir = None  # TMPDIR is read again, as by a new interpreter
                sys.argv = ["-m", *request["args"]]  # runpy puts the module's path first, as -m does
                sys.orig_argv = [sys.executable, "-m", "cosim", *request["args"]]  # what the interpreter was given
                sys.path[0] = os.getcwd()  # -m puts the working folder first
                runpy.run_module("cosim", run_name="__main__", alter_sys=True)
                status = 0  # __main__ leaves with os._exit: reached only if it did not
            except SystemExit as exc:
                status = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
            except BaseException:  # noqa: BLE001 - as an interpreter would: the traceback on stderr, status 1
                import traceback

                traceback.print_exc()
                status = 1
            finally:
                try:
                    sys.stdout.flush()
                    sys.stderr.flush()
                finally:
                    os._exit(status)
        for fd in fds:
            os.close(fd)
        sock.sendall(struct.pack("!q", pid))
        _, wait_status = os.waitpid(pid, 0)
        sock.sendall(struct.pack("!q", wait_status))


class Client:
    """The calling worker's end: :meth:`run` runs one command to its end, as :func:`subprocess.run` with
    ``capture_output=True, text=True`` would."""

    def __init__(self, root: str) -> None:
        import subprocess

        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
        self.proc = subprocess.Popen([sys.executable, __file__, str(theirs.fileno())], cwd=root,
                                     pass_fds=[theirs.fileno()], stdin=subprocess.DEVNULL)
        theirs.close()
        self.sock = ours

    def run(self, args: list[str], cwd: str, env: dict[str, str], timeout: float | None):
        import selectors
        import subprocess
        import time

        out_r, out_w = os.pipe()
        err_r, err_w = os.pipe()
        try:
            socket.send_fds(self.sock, [json.dumps({"args": args, "cwd": cwd, "env": env}).encode()], [out_w, err_w])
        finally:
            os.close(out_w)
            os.close(err_w)
        pid = struct.unpack("!q", self._read(8))[0]
        deadline = None if timeout is None else time.monotonic() + timeout
        chunks: dict[int, list[bytes]] = {out_r: [], err_r: []}
        timed_out = False
        with selectors.DefaultSelector() as sel:
            for fd in chunks:
                sel.register(fd, selectors.EVENT_READ)
            while sel.get_map():
                left = None if deadline is None else deadline - time.monotonic()
                if left is not None and left <= 0:
                    timed_out = True
                    break
                for key, _ in sel.select(left):
                    data = os.read(key.fd, 1 << 16)
                    if data:
                        chunks[key.fd].append(data)
                    else:
                        sel.unregister(key.fd)
        if timed_out:
            try:
                os.kill(pid, 9)
            except ProcessLookupError:
                pass
        status = struct.unpack("!q", self._read(8))[0]
        os.close(out_r)
        os.close(err_r)
        stdout, stderr = (b"".join(chunks[fd]).decode(errors="replace") for fd in (out_r, err_r))
        command = [sys.executable, "-m", "cosim", *args]
        if timed_out:
            raise subprocess.TimeoutExpired(command, timeout, stdout, stderr)
        return subprocess.CompletedProcess(command, os.waitstatus_to_exitcode(status), stdout, stderr)

    def _read(self, n: int) -> bytes:
        data = b""
        while len(data) < n:
            more = self.sock.recv(n - len(data))
            if not more:
                raise RuntimeError(f"the suite's fork server ended (exit {self.proc.wait()})")
            data += more
        return data

    def close(self) -> None:
        self.sock.close()
        self.proc.wait(10)


if __name__ == "__main__":
    sys.path[0] = os.getcwd()  # the repository root (the client starts the server there), as -m would
    _serve(socket.socket(fileno=int(sys.argv[1])))
