#!/usr/bin/env python3
"""Run a command in a private network namespace that has loopback alone, with liblsl
configured to keep discovery on this computer.

usage: tools/private_net.py COMMAND [ARG...]

Everything that loads liblsl here (the LSL tests, a trial by hand) runs through this: the
command sees no interface but loopback, so nothing it sends can leave the machine, and
``LSLAPICFG`` names hapticlab's machine-scope configuration. The command's exit status is
this script's; 2 when no namespace could be made (the reason on stderr).
"""

from __future__ import annotations

import fcntl
import os
import shutil
import socket
import struct
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
_INSIDE = "_HAPTICLAB_PRIVATE_NET"  # set once the command runs inside the namespace
_SIOCGIFFLAGS, _SIOCSIFFLAGS, _IFF_UP = 0x8913, 0x8914, 0x1


def _fail(msg: str) -> None:
    print(f"private_net: {msg}", file=sys.stderr)
    sys.exit(2)


def _loopback_up() -> None:
    """Set loopback up (what ``ip link set lo up`` does), with the interface ioctls."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        req = struct.pack("16sh", b"lo", 0)
        flags = struct.unpack("16sh", fcntl.ioctl(s, _SIOCGIFFLAGS, req))[1]
        fcntl.ioctl(s, _SIOCSIFFLAGS, struct.pack("16sh", b"lo", flags | _IFF_UP))


def main(argv: list[str]) -> None:
    if not argv or argv[0] in ("-h", "--help"):
        print(__doc__.strip())
        sys.exit(0 if argv else 2)
    if os.environ.get(_INSIDE) != "1":
        unshare = shutil.which("unshare")
        if unshare is None:
            _fail("no unshare (util-linux) on this machine: cannot make a private network")
        # as root a network namespace alone; otherwise inside a user namespace of one's own
        mapped = [] if os.geteuid() == 0 else ["--map-root-user"]
        os.environ[_INSIDE] = "1"
        os.execv(unshare, [unshare, "--net", *mapped, sys.executable, __file__, *argv])
    try:
        _loopback_up()
    except OSError as exc:
        _fail(f"cannot set loopback up in the new namespace ({exc})")
    sys.path.insert(0, str(ROOT))
    from app.markers import PRIVATE_ENV, machine_config, private_network_problem

    if (why := private_network_problem()) is not None:
        _fail(f"refusing to run {argv[0]}: {why}")
    os.environ["LSLAPICFG"] = str(machine_config())
    os.environ[PRIVATE_ENV] = "1"
    try:
        os.execvp(argv[0], argv)
    except OSError as exc:
        _fail(f"cannot run {argv[0]}: {exc}")


if __name__ == "__main__":
    main(sys.argv[1:])
