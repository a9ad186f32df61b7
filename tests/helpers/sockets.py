"""Which processes listen on which addresses, read from /proc (Linux), for the tests that
check a local run listens on loopback only."""

from __future__ import annotations

import contextlib
import ipaddress
import os
from pathlib import Path


def _listening() -> dict[int, str]:
    """Returns socket inode -> "address:port" for every TCP socket in LISTEN state."""
    out = {}
    for table, width in (("/proc/net/tcp", 4), ("/proc/net/tcp6", 16)):
        with contextlib.suppress(OSError):
            for line in Path(table).read_text().splitlines()[1:]:
                fields = line.split()
                if fields[3] != "0A":  # LISTEN
                    continue
                hex_address, hex_port = fields[1].split(":")
                raw = bytes.fromhex(hex_address)
                # /proc writes each 32-bit word in host (little-endian) order
                words = [raw[i : i + 4][::-1] for i in range(0, len(raw), 4)]
                address = ipaddress.ip_address(b"".join(words)[:width])
                out[int(fields[9])] = f"{address}:{int(hex_port, 16)}"
    return out


def listening_addresses(pids: set[int]) -> dict[int, list[str]]:
    """Returns pid -> the addresses its TCP sockets listen on, for the given processes."""
    sockets = _listening()
    out: dict[int, list[str]] = {}
    for pid in pids:
        with contextlib.suppress(OSError):
            for fd in os.listdir(f"/proc/{pid}/fd"):
                with contextlib.suppress(OSError):
                    target = os.readlink(f"/proc/{pid}/fd/{fd}")
                    if target.startswith("socket:["):
                        inode = int(target[8:-1])
                        if inode in sockets:
                            out.setdefault(pid, []).append(sockets[inode])
    return out


def is_loopback(address: str) -> bool:
    """Whether "host:port" listens on a loopback address (IPv4-mapped IPv6 included)."""
    host = ipaddress.ip_address(address.rsplit(":", 1)[0])
    mapped = getattr(host, "ipv4_mapped", None)
    return (mapped or host).is_loopback
