"""``fourbar-view``: a run folder in the browser, live or replayed; or an animation for a report.

Exit codes: 0 the animation written, 1 the animation file could not be written after all, 2
usage error (an animation option or an unwritable animation output too), not a run folder, or a
port in use, 130 / 143 the server
stopped by Ctrl-C / SIGTERM (the view writes nothing, so a signal loses nothing).  Heavy imports (Panel, Bokeh, matplotlib)
happen after the arguments are checked, so ``--help`` answers at once.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Sequence

from fourbar_common.version import VersionAction

__all__ = ["main"]

_DESCRIPTION = """\
Show a run folder (written by fourbar-run, with the monitor's and the diagnosis' outputs
when they exist) in a web browser: the mechanism drawn and moving, the monitored signal
with its forecast and the training window, the detector statistic against its limit, the
monitor's state (TRAINING / STABLE / ALARM, with the paper's message at the alarm), the
diagnosis when fourbar-diagnose has written it, and the run's facts.  While fourbar-run and
`fourbar-monitor --follow` write the folder, the page follows them; a finished run is
played back at --speed, with pause and a time slider.  The view reads files only and
serves on 127.0.0.1 (this computer only) unless --address says otherwise; the page has no
authentication.  It answers only requests addressed to the name it serves (the Host header:
127.0.0.1, localhost or [::1] with its port; others get 403) and ignores BOKEH_* environment
variables (--allow-host admits another name).
"""

_EPILOG = """\
examples:
  fourbar-view out/case2_fault_L2                   # serve it; open the URL it prints
  fourbar-view out/case2_fault_L2 --speed 5         # replay a finished run 5x faster
  fourbar-view out/case2_fault_L2 --animate case2.gif   # an animation for a report (no server)
  fourbar-view out/case2_fault_L2 --address 0.0.0.0 --port 5006   # other computers too (no authentication!)

The page and its controls: docs/view.md.  Stop the server with Ctrl-C (the view writes
nothing, so stopping it loses nothing).
exit status: 0 animation written, 1 the animation file could not be written after all,
2 usage error (an --animate output that cannot be written too, checked before any frame is
drawn), not a run folder, or the port in use, 130 server stopped by Ctrl-C, 143 server stopped
by SIGTERM.
"""


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"expected a number > 0, got {text}")
    return value


def _port(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a port number, got {text!r}") from None
    if not 0 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"expected a port number 0-65535 (0: any free port), got {value}")
    return value


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="fourbar-view", description=_DESCRIPTION, epilog=_EPILOG,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("run_dir", metavar="RUN_DIR", help="the run folder (fourbar-run --out; default out/<case>)")
    parser.add_argument("--port", type=_port, default=0,
                        help="port to serve on (default 0: a free port, printed)")
    parser.add_argument("--address", default="127.0.0.1", metavar="HOST",
                        help="address to serve on (default 127.0.0.1: this computer only; another address, "
                             "e.g. 0.0.0.0, lets other computers read the page, which has no authentication: a "
                             "warning says so)")
    parser.add_argument("--allow-host", action="append", default=[], metavar="HOST[:PORT]",
                        help="also answer requests (and websocket origins) naming this host, e.g. a proxy's "
                             "name; repeatable.  BOKEH_ALLOW_WS_ORIGIN and other BOKEH_* variables are ignored")
    parser.add_argument("--speed", type=_positive, default=1.0,
                        help="replay speed of a finished run (and of --animate): simulated seconds per "
                             "second (default 1)")
    parser.add_argument("--at", type=float, metavar="SECONDS",
                        help="open the page paused at this run time (default: follow a running run, replay a "
                             "finished one from its start)")
    parser.add_argument("--window", type=_positive, default=20.0,
                        help="seconds of signal and forecast shown at full resolution (default 20)")
    parser.add_argument("--animate", metavar="OUT", help="write an animation (.gif, or .mp4 when ffmpeg exists) "
                                                       "of the mechanism and its signal instead of serving")
    parser.add_argument("--fps", type=_positive, default=20.0, help="--animate: frames per second (default 20)")
    parser.add_argument("--start", type=float, help="--animate: first run time shown, s (default: 5 s before the "
                                                    "fault, or the run's start)")
    parser.add_argument("--stop", type=float, help="--animate: last run time shown, s (default: 10 s after the "
                                                   "fault, 15 s after --start)")
    parser.add_argument("--width", type=int, default=640, help="--animate: width in pixels (default 640)")
    parser.add_argument("--quiet", "-q", action="store_true", help="print only the URL (or the animation's path)")
    parser.add_argument("--version", action=VersionAction)
    return parser


def _any_free_port(host: str = "127.0.0.1") -> int:
    """A port on ``host`` that no one listens on now (the system's choice)."""
    from .served import _socket_for

    with _socket_for(host, 0) as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


def main(argv: Sequence[str] | None = None) -> int:
    from fourbar_common.signals import StopSignals, exit_code, signal_of

    with StopSignals():
        try:
            return _main(argv)
        except KeyboardInterrupt as exc:
            signum = signal_of(exc)
            print("fourbar-view: stopped; the view writes nothing, so nothing is lost", file=sys.stderr, flush=True)
            return exit_code(signum)


def _main(argv: Sequence[str] | None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:
        return int(exc.code or 0)
    from .sources import RunFolderError, check_run_folder

    try:
        folder = check_run_folder(args.run_dir)
    except RunFolderError as exc:
        print(f"fourbar-view: error: {exc}", file=sys.stderr)
        return 2
    if args.animate is not None:
        return _animate(folder, Path(args.animate), args)
    from .served import AddressError, parse_address

    host = args.address.strip()
    if ":" in host and not host.startswith("["):        # --address names a host only; an IPv6 one bare
        host = f"[{host}]"
    try:
        bind = parse_address(host, args.port, option="--address")
    except AddressError as exc:
        print(f"fourbar-view: error: {exc}", file=sys.stderr)
        return 2
    if bind.port != args.port:
        print(f"fourbar-view: error: --address {args.address!r}: give the port with --port", file=sys.stderr)
        return 2
    problem = bind.listen_problem("--address", "--port")
    if problem is not None:
        print(f"fourbar-view: error: {problem}", file=sys.stderr)
        return 2
    return serve(folder, port=bind.port, address=bind.host, allow_hosts=tuple(args.allow_host), speed=args.speed,
                 window=args.window, at=args.at, quiet=args.quiet)


def serve(folder: Path, *, port: int = 0, address: str = "127.0.0.1", allow_hosts: tuple[str, ...] = (),
          speed: float = 1.0, window: float = 20.0, at: float | None = None, quiet: bool = False,
          on_ready=None) -> int:
    """Serve the page of ``folder`` on ``address``:``port`` until Ctrl-C / SIGTERM; prints the URL.

    Every session shares one reader of the folder (:class:`~view.page.SharedRun`).  Requests
    whose Host header is not a name of the bound address (or of ``allow_hosts``) get 403, the
    websocket accepts only those origins, and BOKEH_* environment variables are dropped first
    (:mod:`view.served`)."""
    import logging
    import signal

    from .served import Bind, ignore_bokeh_environment, refuse_other_hosts

    ignored = ignore_bokeh_environment()   # before Bokeh is imported and reads them
    import panel as pn

    from .page import PageSettings, RunPage, SharedRun

    if ignored and not quiet:
        print(f"fourbar-view: note: ignoring {', '.join(ignored)} from the environment (use --allow-host to admit "
              f"another host)", file=sys.stderr)
    settings = PageSettings(speed=speed, window_s=window, at=at)
    shared = SharedRun(folder, settings.poll_ms / 1000)
    for name in ("bokeh", "tornado", "panel"):
        logging.getLogger(name).setLevel(logging.ERROR)

    def page():
        return RunPage(shared, settings).servable()

    if port == 0:
        port = _any_free_port(address)
    bind = Bind(address, port)
    hosts = bind.host_names(allow_hosts)
    warning = bind.warning("fourbar-view")
    if warning:
        print(f"fourbar-view: {warning}", file=sys.stderr, flush=True)
    # Panel's serve() replaces the SIGINT handler by one that stops the loop quietly (the
    # command then ended 0 with nothing said); the StopSignals handler of main() is put back,
    # so Ctrl-C ends the server as SIGTERM does: the "stopped" line and 130
    keep_sigint = signal.getsignal(signal.SIGINT)
    try:
        server = pn.serve({"/": page}, port=port, address=address, show=False, start=False, threaded=False,
                          title=f"fourbar-view: {folder.name}",
                          # Bokeh's origin list cannot hold an IPv6 literal ([::1]:PORT): those names
                          # pass the Host check but open no websocket
                          websocket_origin=[h for h in hosts if h.count(":") == 1],
                          check_unused_sessions=2000, unused_session_lifetime=5000, verbose=False)
    except OSError as exc:                 # taken between the check and now
        print(f"fourbar-view: error: port {port} on {address}: {exc.strerror}; choose another with --port",
              file=sys.stderr)
        return 2
    finally:
        if keep_sigint is not None:
            try:
                signal.signal(signal.SIGINT, keep_sigint)
            except ValueError:         # not the main thread: Panel could not replace it either
                pass
    refuse_other_hosts(server._tornado, hosts)     # Bokeh's Server keeps its Tornado application there
    url = bind.url
    if quiet:
        print(url, flush=True)
    else:
        where = f" (listening on {bind.where}: every interface)" if bind.wildcard else ""
        print(f"fourbar-view: {folder} at {url}{where}  (Ctrl-C to stop)", flush=True)
    if on_ready is not None:
        on_ready(url)
    server.start()
    try:
        server.io_loop.start()
    finally:
        server.stop()
    return 0


def _animate(folder: Path, out: Path, args) -> int:
    from .animate import AnimationError, animate
    from .sources import RunFolderError

    try:
        result = animate(folder, out, fps=args.fps, speed=args.speed, start=args.start, stop=args.stop,
                         width_px=args.width)
    except (AnimationError, RunFolderError) as exc:
        print(f"fourbar-view: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"fourbar-view: error: cannot write {out}: {exc.strerror or exc}", file=sys.stderr)
        return 1
    print(f"fourbar-view: wrote {result.path} ({result.frames} frames, t = {result.start:g}-{result.stop:g} s, "
          f"{result.bytes / 1e6:.2f} MB)")
    if result.not_drawn:
        print(f"fourbar-view: the mechanism is not drawn: {result.not_drawn}", file=sys.stderr)
    return 0


if __name__ == "__main__":          # pragma: no cover
    sys.exit(main())
