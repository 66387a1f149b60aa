"""Which OPC UA endpoints a server may connect to (``FURNACE_TWIN_OPCUA_ENDPOINTS``; loopback by default).

An allow-list is a comma-separated list of entries; an endpoint ``opc.tcp://HOST:PORT/path`` is allowed
when one entry matches its host (and its port, if the entry names one):

* a host name (``localhost``, ``furnace-plc.lab``), compared literally (no DNS lookup: what is checked is
  what is connected to);
* an IP address (``10.0.0.5``, ``::1``) or a network (``10.0.0.0/24``), for endpoints given by address;
* any of these with ``:PORT`` (IPv6 in brackets: ``[::1]:4840``), or a whole ``opc.tcp://HOST:PORT`` URL.

Example
-------
>>> allowed = parse_allow_list("127.0.0.1, localhost, 10.0.0.0/24:4840")
>>> endpoint_allowed("opc.tcp://127.0.0.1:4840/furnace-twin/", allowed)
True
>>> endpoint_allowed("opc.tcp://10.0.0.7:4840/", allowed), endpoint_allowed("opc.tcp://10.0.0.7:4841/", allowed)
(True, False)
>>> parse_endpoint("http://x:1/")
Traceback (most recent call last):
...
ValueError: 'http://x:1/' is not an OPC UA endpoint: it must start with opc.tcp://
"""

from __future__ import annotations

import ipaddress
from dataclasses import dataclass
from urllib.parse import urlsplit

DEFAULT_PORT = 4840  # the IANA port of OPC UA
LOOPBACK_ALLOW_LIST = "127.0.0.1,::1,localhost"


@dataclass(frozen=True)
class Endpoint:
    """An ``opc.tcp://`` URL split into what the allow-list checks."""

    url: str
    host: str
    port: int


@dataclass(frozen=True)
class AllowEntry:
    host: str | None  # a literal host name (lower case), or None for a network
    network: ipaddress.IPv4Network | ipaddress.IPv6Network | None
    port: int | None

    def matches(self, ep: Endpoint) -> bool:
        if self.port is not None and self.port != ep.port:
            return False
        if self.host is not None:
            return self.host == ep.host.lower()
        try:
            address = ipaddress.ip_address(ep.host)
        except ValueError:
            return False
        assert self.network is not None
        return address.version == self.network.version and address in self.network


def parse_endpoint(url: str) -> Endpoint:
    """Split an ``opc.tcp://host[:port][/path]`` URL; ``ValueError`` with a message if it is not one."""
    text = url.strip()
    if not text.lower().startswith("opc.tcp://"):
        raise ValueError(f"{url!r} is not an OPC UA endpoint: it must start with opc.tcp://")
    try:
        parts = urlsplit(text)
        port = parts.port
    except ValueError as exc:
        raise ValueError(f"{url!r} is not a valid endpoint URL: {exc}") from None
    if not parts.hostname:
        raise ValueError(f"{url!r} names no host")
    if parts.username or parts.password:
        raise ValueError(f"{url!r}: put no credentials in the URL (set FURNACE_TWIN_OPCUA_USERNAME / _PASSWORD)")
    return Endpoint(url=text, host=parts.hostname, port=port if port is not None else DEFAULT_PORT)


def _split_port(text: str) -> tuple[str, int | None]:
    if text.lower().startswith("opc.tcp://"):
        ep = parse_endpoint(text)
        explicit = urlsplit(text).port
        return ep.host, explicit
    if text.startswith("["):  # [v6]:port
        host, _, rest = text[1:].partition("]")
        return host, int(rest[1:]) if rest.startswith(":") else None
    if text.count(":") == 1:  # host:port or v4:port (a bare v6 address has several colons)
        host, port = text.split(":")
        return host, int(port)
    return text, None


def parse_allow_list(text: str) -> tuple[AllowEntry, ...]:
    """The entries of a comma-separated allow-list; ``ValueError`` naming a bad entry."""
    entries = []
    for raw in text.split(","):
        item = raw.strip()
        if not item:
            continue
        try:
            host, port = _split_port(item)
        except ValueError as exc:
            raise ValueError(f"allow-list entry {item!r}: {exc}") from None
        if port is not None and not 0 < port < 65536:
            raise ValueError(f"allow-list entry {item!r}: port {port} out of range")
        try:
            network = ipaddress.ip_network(host, strict=False)
        except ValueError:
            if not host or "/" in host:
                raise ValueError(f"allow-list entry {item!r} is not a host, address or network") from None
            entries.append(AllowEntry(host=host.lower(), network=None, port=port))
        else:
            entries.append(AllowEntry(host=None, network=network, port=port))
    return tuple(entries)


def endpoint_allowed(url: str, allowed: tuple[AllowEntry, ...]) -> bool:
    """Whether ``url`` (a valid endpoint) matches an entry of the allow-list."""
    ep = parse_endpoint(url)
    return any(e.matches(ep) for e in allowed)


def is_loopback(host: str) -> bool:
    """``localhost`` or a loopback address (for the emulator's insecure-serving guard)."""
    if host.lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False
