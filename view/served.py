"""Where a page server listens and whom it answers: the view's and the sweep dashboard's one
home for the bind address, the Host check and the websocket origins.

Both serve Bokeh pages with no authentication, so by default they listen on 127.0.0.1 only.
A browser on this computer is still a way in: a web page elsewhere can point a name it owns at
127.0.0.1 (DNS rebinding) and read what the server answers, and Bokeh's websocket accepts any
Origin that ``BOKEH_ALLOW_WS_ORIGIN`` names.  So:

- :func:`refuse_other_hosts` answers 403 to a request whose ``Host`` header is not one of the
  bound address's names (``127.0.0.1:PORT``, ``localhost:PORT``, ``[::1]:PORT`` on loopback;
  the given address, and for a wildcard address this computer's names, otherwise), before any
  handler runs: neither Bokeh nor Panel has a Host allowlist (Bokeh checks only a websocket's
  Origin), so this wraps Tornado's ``Application.find_handler``;
- :func:`ignore_bokeh_environment` drops every ``BOKEH_*`` variable from the environment before
  Bokeh reads it (``BOKEH_ALLOW_WS_ORIGIN`` replaces the origin list; ``BOKEH_AUTH_MODULE`` runs
  a file); a host is admitted by a flag only (``--allow-host``).
"""
from __future__ import annotations

import ipaddress
import os
import socket
from dataclasses import dataclass
from typing import Iterable

__all__ = ["Bind", "AddressError", "parse_address", "ignore_bokeh_environment", "refuse_other_hosts",
           "LOOPBACK_NAMES"]

#: The names a browser on this computer uses for the loopback address.
LOOPBACK_NAMES = ("127.0.0.1", "localhost", "[::1]")
_WILDCARDS = ("0.0.0.0", "::")


class AddressError(ValueError):
    """An address that cannot be served on; the message names it and why."""


def _bracketed(host: str) -> str:
    return f"[{host}]" if ":" in host else host


@dataclass(frozen=True)
class Bind:
    """An address and port a server listens on."""

    host: str            # as given to bind(): 127.0.0.1, 0.0.0.0, ::, 192.168.1.5, a name
    port: int

    @property
    def loopback(self) -> bool:
        """Only this computer can connect."""
        if self.host == "localhost":
            return True
        try:
            return ipaddress.ip_address(self.host).is_loopback
        except ValueError:
            try:
                return all(ipaddress.ip_address(info[4][0]).is_loopback
                           for info in socket.getaddrinfo(self.host, None))
            except (OSError, ValueError):
                return False

    @property
    def wildcard(self) -> bool:
        return self.host in _WILDCARDS

    @property
    def where(self) -> str:
        """``HOST:PORT`` as bound."""
        return f"{_bracketed(self.host)}:{self.port}"

    @property
    def url(self) -> str:
        """The link to print: the address bound (this computer's name when bound to all of them)."""
        host = socket.gethostname() if self.wildcard else _bracketed(self.host)
        return f"http://{host}:{self.port}/"

    def names(self) -> tuple[str, ...]:
        """The names a request may give this server by (lower case, IPv6 in brackets, no port):
        127.0.0.1, localhost, [::1] on loopback; the address otherwise, and this computer's
        names and addresses too when bound to all of them."""
        if self.loopback:
            names = set(LOOPBACK_NAMES) | {_bracketed(self.host)}
        elif self.wildcard:
            names = set(LOOPBACK_NAMES) | {socket.gethostname(), socket.getfqdn()}
            try:
                names |= {_bracketed(info[4][0]) for info in socket.getaddrinfo(socket.gethostname(), None)}
            except OSError:
                pass
        else:
            names = {_bracketed(self.host)}
        return tuple(sorted(n.lower() for n in names))

    def host_names(self, extra: Iterable[str] = ()) -> tuple[str, ...]:
        """The ``Host`` header values served, lower case, each ``name:port``; ``extra`` (from
        --allow-host) as given, with this port when it names none."""
        hosts = {f"{n}:{self.port}" for n in self.names()}
        for e in extra:
            e = e.strip().lower()
            hosts.add(e if e.rsplit(":", 1)[-1].isdigit() and not e.endswith("]") else f"{e}:{self.port}")
        return tuple(sorted(hosts))

    def listen_problem(self, address_option: str, port_option: str | None = None) -> str | None:
        """Why this address and port cannot be listened on now (None: they can; port 0 can
        whenever the address is one of this computer's), naming the options to change."""
        try:
            with _socket_for(self.host, self.port) as s:
                s.bind((self.host, self.port))
        except OSError as exc:
            why = exc.strerror or str(exc)
            if self.port == 0:
                return f"{address_option} {self.host}: cannot listen there ({why}); is it an address of this computer?"
            change = f"{port_option}" if port_option else address_option
            return (f"port {self.port} on {self.host} cannot be served on ({why}); choose another with {change}"
                    + (f", or {port_option} 0" if port_option else ""))
        return None

    def warning(self, what: str) -> str | None:
        """What to say when the address is reachable from other computers (None: loopback)."""
        if self.loopback:
            return None
        return (f"warning: {what} listens on {self.where}, reachable from other computers, and has no "
                f"authentication: anyone who can reach this address can read it. Bind 127.0.0.1 (the default) "
                f"unless you mean this")


def _socket_for(host: str, port: int) -> socket.socket:
    family = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)[0][0]
    return socket.socket(family, socket.SOCK_STREAM)


def parse_address(text: str, default_port: int, *, option: str) -> Bind:
    """``HOST``, ``HOST:PORT``, ``:PORT`` (127.0.0.1), ``PORT`` or ``[V6]:PORT`` as a :class:`Bind`;
    :class:`AddressError` naming ``option`` and the text."""
    raw = text.strip()
    if "/" in raw:
        raise AddressError(f"{option} {text!r}: expected HOST[:PORT] (e.g. 127.0.0.1:8787), not a URL")
    host, port_text = raw, None
    if raw.startswith("["):
        close = raw.find("]")
        if close < 0:
            raise AddressError(f"{option} {text!r}: an IPv6 address needs its closing ']', e.g. [::1]:8787")
        host, rest = raw[1:close], raw[close + 1:]
        if rest:
            if not rest.startswith(":"):
                raise AddressError(f"{option} {text!r}: expected [ADDRESS]:PORT")
            port_text = rest[1:]
    elif raw.isdigit():
        host, port_text = "", raw
    elif raw.count(":") == 1:
        host, port_text = raw.split(":")
    elif raw.count(":") > 1:
        raise AddressError(f"{option} {text!r}: write an IPv6 address in brackets, e.g. [::1]:8787")
    host = host or "127.0.0.1"
    port = default_port
    if port_text is not None:
        if not port_text.isdigit() or not 0 <= int(port_text) <= 65535:
            raise AddressError(f"{option} {text!r}: expected a port number 0-65535 after the ':'")
        port = int(port_text)
    try:
        socket.getaddrinfo(host, None)
    except OSError as exc:
        raise AddressError(f"{option} {text!r}: {host!r} is not an address of this computer's resolver "
                           f"({exc.strerror or exc})") from None
    return Bind(host, port)


def ignore_bokeh_environment(environ=os.environ) -> list[str]:
    """Remove every ``BOKEH_*`` variable from ``environ``; the names removed (to say so).
    Bokeh reads them when it serves, and ``BOKEH_ALLOW_WS_ORIGIN`` *replaces* the server's
    websocket origins: an environment inherited from elsewhere must not widen who may connect."""
    names = sorted(k for k in environ if k.upper().startswith("BOKEH_"))
    for k in names:
        del environ[k]
    return names


def host_allowed(host_header: str | None, allowed: Iterable[str]) -> bool:
    """Whether a request's ``Host`` header is one of ``allowed`` (``name:port``; a header
    without a port means port 80)."""
    if not host_header:
        return False
    h = host_header.strip().lower()
    if not (h.rsplit(":", 1)[-1].isdigit() and not h.endswith("]")):
        h += ":80"
    return h in set(allowed)


def refuse_other_hosts(app, allowed: Iterable[str]) -> None:
    """Make the Tornado application ``app`` answer 403 to any request whose Host header is not
    in ``allowed``, before routing (so no session or document is made for it)."""
    from tornado import web

    allowed = frozenset(allowed)

    class RefusedHost(web.RequestHandler):
        def prepare(self) -> None:
            self.set_status(403)
            self.set_header("Content-Type", "text/plain; charset=utf-8")
            self.finish(f"403: Host {self.request.host!r} is not served here; this server answers "
                        f"{', '.join(sorted(allowed))}\n")

    find = app.find_handler

    def find_handler(request, **kwargs):
        if not host_allowed(request.headers.get("Host"), allowed):
            return app.get_handler_delegate(request, RefusedHost)
        return find(request, **kwargs)

    app.find_handler = find_handler
