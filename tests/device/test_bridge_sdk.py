"""What a lab meets before a bridge runs (issue 52): `make -C firmware check-sdk`, the
documented build commands against an SDK laid out as each vendor installs it, and every
missing prerequisite named with what provides it.

The SDK folders here hold hapticlab's stand-ins (firmware/stubs/), whose headers have the
vendors' macro structure (OpenHaptics' `#if defined(linux)` and stdcall macros, Force
Dimension's C++-only headers) and the vendors' constant values: what fails against the
vendors' own headers fails here too. The vendors' headers are not in this repository; they
were compiled against by hand (docs/howto/run-on-your-device.md says which versions and
with what result).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from device.serial.backend import SerialDevice
from device.serial.firmware import FIRMWARE_DIR, binary

pytestmark = [pytest.mark.integration, pytest.mark.firmware, pytest.mark.realtime]

STUBS = FIRMWARE_DIR / "stubs"
RATINGS = "-DHL_EFFECTIVE_MASS_MG=55000u -DHL_CURRENT_RATING_MA=400u -DHL_ENCODER_NM=2000u"


def _cc(*args: str) -> None:
    run = subprocess.run(["cc", "-std=c11", "-O1", "-D_DEFAULT_SOURCE", *args],
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stderr


def _make(*args: str, env: dict | None = None, wrap: tuple = ()) -> subprocess.CompletedProcess:
    return subprocess.run([*wrap, "make", "--no-print-directory", "-C", str(FIRMWARE_DIR), *args],
                          capture_output=True, text=True, timeout=300, env=env)


def dhd_sdk(root: Path, header_edit=None, lib_defines: tuple[str, ...] = (),
            shared: bool = False) -> Path:
    """A Force Dimension SDK folder as the vendor lays it out: its C++ headers in include/,
    libdrd (which holds libdhd) in lib/release/lin-x86_64-gcc; here the stand-in, packed as
    that library. `header_edit(text) -> text` changes dhdc.h first; `lib_defines` compile
    the library otherwise (an older SDK's); `shared` packs it as the SDK's shared library,
    libdrd.so.3.17.5 with the links its install guide makes (libdrd.so.3, libdrd.so)."""
    binary("dhd-stub")  # the stand-in's own SDK check (build/stub-sdk/hl_sdk_dhd.h)
    sdk = root / "fd-sdk"
    (sdk / "include").mkdir(parents=True)
    for h in ("dhdc.h", "drdc.h"):
        text = (STUBS / "dhd" / "include" / h).read_text()
        if h == "dhdc.h" and header_edit:
            text = header_edit(text)
        (sdk / "include" / h).write_text(text)
    lib = sdk / "lib" / "release" / "lin-x86_64-gcc"
    lib.mkdir(parents=True)
    objs = []
    for src in (STUBS / "dhd" / "dhd_stub.c", FIRMWARE_DIR / "src" / "plant.c"):
        obj = root / (src.stem + ".o")
        _cc("-c", "-fPIC", f"-I{FIRMWARE_DIR / 'include'}",
            f"-I{FIRMWARE_DIR / 'build' / 'stub-sdk'}", *lib_defines, str(src), "-o", str(obj))
        objs.append(str(obj))
    if shared:
        _cc("-shared", "-Wl,-soname,libdrd.so.3", *objs, "-lm", "-o",
            str(lib / "libdrd.so.3.17.5"))
        (lib / "libdrd.so.3").symlink_to("libdrd.so.3.17.5")
        (lib / "libdrd.so").symlink_to("libdrd.so.3")
    else:
        subprocess.run(["ar", "rcs", str(lib / "libdrd.a"), *objs], check=True)
    return sdk


def openhaptics(root: Path, header_edit=None, driver: bool = True, ldconfig: bool = True) -> Path:
    """An OpenHaptics prefix as its Linux installer lays it out: include/HD/, and libHD.so in
    lib64, which needs the device's driver library (libPHANToMIO.so.4, a one-function
    stand-in here, left out with driver=False), its soname's link made by `ldconfig -n` as
    the how-to says (not with ldconfig=False). `header_edit(text) -> text` changes the
    headers first."""
    prefix = root / "openhaptics"
    (prefix / "include" / "HD").mkdir(parents=True)
    for h in (STUBS / "openhaptics" / "include" / "HD").glob("*.h"):
        text = h.read_text()
        (prefix / "include" / "HD" / h.name).write_text(header_edit(text) if header_edit
                                                        else text)
    lib = prefix / "lib64"
    lib.mkdir()
    (root / "phantomio.c").write_text("int hl_stub_phantom_io(void) { return 0; }\n")
    _cc("-shared", "-fPIC", "-Wl,-soname,libPHANToMIO.so.4", str(root / "phantomio.c"),
        "-o", str(lib / "libPHANToMIO.so.4"))
    _cc("-shared", "-fPIC", "-Dlinux=1", f"-I{FIRMWARE_DIR / 'include'}",
        f"-I{STUBS / 'openhaptics' / 'include'}", str(STUBS / "openhaptics" / "hd_stub.c"),
        str(FIRMWARE_DIR / "src" / "plant.c"), "-Wl,-soname,libHD.so.3.0", "-Wl,--no-as-needed",
        f"-L{lib}", "-l:libPHANToMIO.so.4", "-Wl,-rpath,$ORIGIN", "-lpthread", "-lm",
        "-o", str(lib / "libHD.so.3.0.0"))
    (lib / "libHD.so").symlink_to("libHD.so.3.0.0")
    if ldconfig:
        subprocess.run(["ldconfig", "-n", str(lib)], check=True)
    if not driver:
        (lib / "libPHANToMIO.so.4").unlink()
    return prefix


@pytest.fixture(scope="module")
def fd_sdk(tmp_path_factory) -> Path:
    """One stand-in Force Dimension SDK folder for the tests that only build against it."""
    return dhd_sdk(tmp_path_factory.mktemp("fd"))


def _ratings(**settings: str) -> str:
    """BRIDGE_RATINGS with RATINGS's values, each setting given replaced (None: left out)."""
    given = dict(w[2:].split("=", 1) for w in RATINGS.split())
    given.update(settings)
    return " ".join(f"-D{k}={v}" for k, v in given.items() if v is not None)


@pytest.mark.parametrize(("setting", "value", "said"), [
    # a negative current once built and started ("at most -0.01 N"), the clamp then
    # reading it as 4.3 million A and HELLO_ACK as 65.531 A
    ("HL_CURRENT_RATING_MA", "-5", "HL_CURRENT_RATING_MA must be 1 to 65535 mA"),
    ("HL_CURRENT_RATING_MA", "0u", "HL_CURRENT_RATING_MA must be 1 to 65535 mA"),
    ("HL_CURRENT_RATING_MA", "65536u", "HL_CURRENT_RATING_MA must be 1 to 65535 mA"),
    ("HL_EFFECTIVE_MASS_MG", "0u", "HL_EFFECTIVE_MASS_MG must be 1 to 4294967295 mg"),
    ("HL_EFFECTIVE_MASS_MG", "-55000", "HL_EFFECTIVE_MASS_MG must be 1 to 4294967295 mg"),
    ("HL_ENCODER_NM", "4294967296u", "HL_ENCODER_NM must be 1000 to 4294967000 nm"),
    ("HL_ENCODER_NM", "0u", "HL_ENCODER_NM must be 1000 to 4294967000 nm"),
    ("HL_ENCODER_NM", "1500u", "HL_ENCODER_NM must be a whole number of micrometres"),
])
def test_a_rating_the_device_cannot_carry_is_refused_at_build_once(setting, value, said,
                                                                     fd_sdk, tmp_path):
    """Each rating within what the firmware's clamp and HELLO_ACK hold it in (the current in
    16 bits, from 1 mA; the mass and the encoder's step in 32, from 1 mg and 1 µm), or the
    lab's build stops before anything is compiled, saying so once (the check sits in one
    file, not in each that includes the ratings)."""
    run = _make("dhd", f"DHD_SDK={fd_sdk}", f"BRIDGE_OUT={tmp_path}",
                f"BRIDGE_RATINGS={_ratings(**{setting: value})}")
    out = run.stdout + run.stderr
    assert run.returncode != 0 and not (tmp_path / "hlfw-dhd").exists()
    assert out.count(said) == 1, out
    assert "check-sdk:" not in out  # refused before the SDK is looked at


@pytest.mark.parametrize(("ratings", "said"), [
    (_ratings(HL_CURRENT_RATING_MA=None), "BRIDGE_RATINGS lacks HL_CURRENT_RATING_MA"),
    (_ratings(HL_EFFECTIVE_MASS_MG=None), "BRIDGE_RATINGS lacks HL_EFFECTIVE_MASS_MG"),
    (_ratings(HL_ENCODER_NM=None), "BRIDGE_RATINGS lacks HL_ENCODER_NM"),
    (_ratings(HL_CURRENT_RATING_MA=None, HL_CURRENT_MA="400u"),
     "BRIDGE_RATINGS: -DHL_CURRENT_MA=400u is not a rating"),
    (_ratings() + " -DHL_WATCHDOG_MS=1000u", "-DHL_WATCHDOG_MS=1000u is not a rating"),
    (_ratings(HL_ENCODER_NM=""), "-DHL_ENCODER_NM= has no value"),
    (_ratings() + " -DHL_ENCODER_NM=1000u", "names HL_ENCODER_NM twice"),
])
def test_every_rating_is_the_labs_and_nothing_else_passes(ratings, said, fd_sdk, tmp_path):
    """A real device's build takes each of its three ratings from the lab, none from the
    papers' device (a left-out current once built at 1400 mA, a left-out mass at 55 g, the
    encoder at the Makefile's 1 µm), and refuses a name it does not know (a misspelled
    -DHL_CURRENT_MA once built, silently unused), by name, before anything is compiled."""
    run = _make("dhd", f"DHD_SDK={fd_sdk}", f"BRIDGE_OUT={tmp_path}",
                f"BRIDGE_RATINGS={ratings}")
    out = run.stdout + run.stderr
    assert run.returncode != 0 and not (tmp_path / "hlfw-dhd").exists()
    assert said in out, out
    assert "docs/howto/run-on-your-device.md" in out  # where the ratings are explained
    assert "check-sdk:" not in out


def test_a_real_device_build_has_no_default_rating_even_outside_make():
    """The C side refuses too: compiled as a real device's bridge (HL_REAL_DEVICE) without
    its ratings, the device core names each that is missing rather than taking the papers'
    device's."""
    run = subprocess.run(["cc", "-std=c11", "-fsyntax-only", "-DHL_REAL_DEVICE",
                          f"-I{FIRMWARE_DIR / 'include'}", str(FIRMWARE_DIR / "src" / "device.c")],
                         capture_output=True, text=True)
    assert run.returncode != 0
    for name in ("HL_EFFECTIVE_MASS_MG", "HL_CURRENT_RATING_MA", "HL_ENCODER_NM"):
        assert f"a real device's build needs {name}" in run.stderr, run.stderr


def test_check_sdk_finds_each_stand_in_whole_and_says_its_version(tmp_path):
    """A lab runs `make -C firmware check-sdk` first: it compiles the bridge's declarations
    with the SDK's own headers, prints the version it found and whether the link works."""
    fd = _make("check-sdk", f"DHD_SDK={dhd_sdk(tmp_path)}", f"BRIDGE_OUT={tmp_path}")
    assert fd.returncode == 0, fd.stdout + fd.stderr
    assert "Force Dimension SDK 3.17.5" in fd.stdout and "dhdGetMaxForce present" in fd.stdout
    assert "the Force Dimension bridge links" in fd.stdout
    assert '#define HL_DHD_SDK_VERSION "3.17.5"' in (tmp_path / "sdk" / "hl_sdk_dhd.h").read_text()
    oh = _make("check-sdk", f"OPENHAPTICS={openhaptics(tmp_path)}", f"BRIDGE_OUT={tmp_path}")
    assert oh.returncode == 0, oh.stdout + oh.stderr
    assert "OpenHaptics 3.00 (build 66)" in oh.stdout
    assert "the OpenHaptics bridge links" in oh.stdout
    bare = _make("check-sdk")
    assert bare.returncode != 0 and "needs DHD_SDK=" in bare.stdout


def test_a_library_older_than_its_headers_is_named_by_check_sdk(tmp_path):
    """SDK 3.17.5's headers over SDK 3.7.0's libdrd: the headers declare dhdGetMaxForce, so
    the bridge calls it, and the library lacks it. The link probe references every function
    the bridge calls (it called dhdGetSDKVersion alone, and said "links"), so check-sdk names
    the function and both versions instead of the build's bare undefined reference."""
    sdk = dhd_sdk(tmp_path, lib_defines=("-DHL_DHD_HAS_MAX_FORCE=0",
                                          "-DHL_STUB_DHD_SDK_VERSION=3,7,0"))
    run = _make("check-sdk", f"DHD_SDK={sdk}", f"BRIDGE_OUT={tmp_path}")
    out = run.stdout + run.stderr
    assert run.returncode != 0, out
    assert "the Force Dimension bridge links" not in out
    assert ("lacks dhdGetMaxForce, which the SDK's headers (3.17.5) declare and the bridge "
            "calls") in out, out
    assert "the library is older than its headers: it says it is 3.7.0" in out, out


def test_an_sdk_with_its_shared_library_links_and_loads(tmp_path):
    """An SDK folder holding the shared libdrd.so.3.17.5 and the links its install guide
    makes (libdrd.so.3, libdrd.so): -ldrd takes the shared library, so the bridge needs the
    folder in its run path (the Force Dimension flags had none: check-sdk then advised
    `ldconfig -n` for a link that existed). And where the lab's own DHD_LIBS leave the run
    path out, check-sdk says that, not the wrong remedy."""
    sdk = dhd_sdk(tmp_path, shared=True)
    run = _make("dhd", f"DHD_SDK={sdk}", f"BRIDGE_OUT={tmp_path}",
                f"BRIDGE_RATINGS={RATINGS}")
    assert run.returncode == 0, run.stdout + run.stderr
    assert "the Force Dimension bridge links" in run.stdout
    out = subprocess.run(["timeout", "-s", "INT", "2", str(tmp_path / "hlfw-dhd")],
                         capture_output=True, text=True, timeout=30)
    assert out.stdout.startswith("/dev/"), out.stderr
    lib = sdk / "lib" / "release" / "lin-x86_64-gcc"
    bare = _make("check-sdk", f"DHD_SDK={sdk}", f"BRIDGE_OUT={tmp_path}",
                 f"DHD_LIBS=-L{lib} -ldrd -lm -lpthread")
    assert bare.returncode != 0
    assert f"{lib} holds libdrd.so.3, but the loader does not look there" in bare.stdout, (
        bare.stdout)
    assert "ldconfig -n" not in bare.stdout


def test_a_wrong_or_relative_sdk_folder_is_said_as_such(fd_sdk, tmp_path):
    """A folder that holds no SDK is said to hold none, not taken for a missing DHD_SDK; a
    relative folder is the caller's (make -C leaves the shell's PWD as it was), as a lab
    typing `make -C firmware check-sdk DHD_SDK=sdk` means it."""
    wrong = tmp_path / "nothing-here"
    for target, var, needs in (("dhd", "DHD_SDK", "include/dhdc.h"),
                               ("hd", "OPENHAPTICS", "include/HD/hd.h")):
        run = _make(target, f"{var}={wrong}", f"BRIDGE_OUT={tmp_path}",
                    f"BRIDGE_RATINGS={RATINGS}")
        assert run.returncode != 0
        assert f"{var}={wrong} does not hold {needs}" in run.stdout, run.stdout
    caller = fd_sdk.parent
    rel = subprocess.run(["make", "--no-print-directory", "-C", str(FIRMWARE_DIR), "check-sdk",
                          f"DHD_SDK={fd_sdk.name}", f"BRIDGE_OUT={tmp_path}"], cwd=caller,
                         env={**os.environ, "PWD": str(caller)}, capture_output=True,
                         text=True, timeout=300)
    assert rel.returncode == 0, rel.stdout + rel.stderr
    assert f"Force Dimension SDK 3.17.5 ({fd_sdk}/include)" in rel.stdout, rel.stdout


def _swap(old: str, new: str):
    def edit(text: str) -> str:
        return text.replace(old, new)
    edit.old = old
    return edit


@pytest.mark.parametrize(("target", "edit", "named"), [
    ("dhd", _swap("int __SDK dhdGetPosition(double *px, double *py, double *pz",
                  "int __SDK dhdGetPosition(float *px, float *py, float *pz"), "dhdGetPosition"),
    ("dhd", _swap("#define DHD_ON 1", "#define DHD_ON 2"), "DHD_ON differs"),
    ("dhd", _swap("#define DHD_MAX_STATUS 17", "#define DHD_MAX_STATUS 40"), "DHD_MAX_STATUS"),
    ("dhd", _swap("#define DHD_FORCE_OFF_BUTTON 1\n", ""), "DHD_FORCE_OFF_BUTTON"),
    ("hd", _swap("hdGetDoublev(HDenum pname, HDdouble *params)",
                 "hdGetDoublev(HDenum pname, HDfloat *params)"), "hdGetDoublev"),
    ("hd", _swap("#define HD_DEVICE_SERIAL_NUMBER 0x2504",
                 "#define HD_DEVICE_SERIAL_NUMBER 0x2601"),
     "HD_DEVICE_SERIAL_NUMBER is not 0x2504"),
])
def test_check_sdk_names_what_differs_in_a_labs_sdk(target, edit, named, tmp_path):
    """A lab's SDK whose signature or constant differs from what the bridge was written
    against fails the check, and the build after it, with the function or constant named
    (issue 52, problem 5: the Force Dimension bridge compiles against its own C
    declarations, which nothing compared with a lab's headers before)."""
    folder = dhd_sdk(tmp_path, edit) if target == "dhd" else openhaptics(tmp_path, edit)
    headers = "".join(h.read_text() for h in (folder / "include").rglob("*.h"))
    assert edit.old not in headers  # the lab's SDK does differ
    var = f"{'DHD_SDK' if target == 'dhd' else 'OPENHAPTICS'}={folder}"
    run = _make("check-sdk", var, f"BRIDGE_OUT={tmp_path}")
    assert run.returncode != 0
    assert named in run.stdout + run.stderr, run.stdout + run.stderr
    assert "differs from what the bridge calls" in run.stdout
    build = _make(target, var, f"BRIDGE_RATINGS={RATINGS}", f"BRIDGE_OUT={tmp_path}")
    assert build.returncode != 0 and not (tmp_path / f"hlfw-{target}").exists()


def test_the_stand_in_headers_fail_as_the_vendors_do_without_the_bridges_flags(tmp_path):
    """The stand-ins keep the vendors' traps, so that `make test` would catch a build that
    only works over our own headers (issue 52, problems 1, 2 and 11): OpenHaptics' macros
    exist only where `linux` is defined, which -std=c11 leaves out; its stdcall callback is
    a -Wattributes warning, an error under -Werror, and so is its MSVC pragma unless it is a
    system header (-isystem); Force Dimension's headers are C++."""
    inc = f"-I{STUBS / 'openhaptics' / 'include'}"
    src = tmp_path / "cb.c"
    src.write_text("#include <HD/hd.h>\n"
                   "HDCallbackCode HDCALLBACK cb(void *d) { return d ? 0u : 1u; }\n")
    flags = ["cc", "-std=c11", "-Wall", "-Werror", "-fsyntax-only", inc, str(src)]
    no_linux = subprocess.run(flags, capture_output=True, text=True)
    assert no_linux.returncode != 0 and "HDAPI" in no_linux.stderr
    stdcall = subprocess.run([*flags, "-Dlinux=1"], capture_output=True, text=True)
    assert stdcall.returncode != 0 and "stdcall" in stdcall.stderr
    pragma = subprocess.run([*flags, "-Dlinux=1", "-Wno-attributes"], capture_output=True,
                            text=True)  # included as a user's header, not -isystem
    assert pragma.returncode != 0 and "unknown-pragmas" in pragma.stderr
    c_only = tmp_path / "fd.c"
    c_only.write_text("#include <dhdc.h>\n")
    as_c = subprocess.run(["cc", "-std=c11", "-fsyntax-only", f"-I{STUBS / 'dhd' / 'include'}",
                           str(c_only)], capture_output=True, text=True)
    assert as_c.returncode != 0


@pytest.mark.slow
@pytest.mark.parametrize("target", ["dhd", "hd"])
def test_the_labs_build_command_builds_a_bridge_against_an_installed_sdk(target, tmp_path):
    """`make -C firmware dhd DHD_SDK=...` and `make -C firmware hd OPENHAPTICS=...` exactly as
    the how-to gives them, against SDK folders laid out as the vendors install them
    (libdrd under lib/release/lin-x86_64-gcc; libHD in lib64, found again at run time once
    its soname's link is made there, as the how-to says),
    the lab's ratings naming its own encoder resolution (which collided with the Makefile's
    before). Nothing else is overridden: the build runs check-sdk, the prerequisite check
    and the compile with -Werror, and the bridge answers HELLO with the lab's ratings."""
    var = (f"DHD_SDK={dhd_sdk(tmp_path)}" if target == "dhd"
           else f"OPENHAPTICS={openhaptics(tmp_path, ldconfig=False)}")
    make = [target, var, f"BRIDGE_OUT={tmp_path}"]  # never over a lab's own build/hlfw-*
    bare = _make(*make)
    assert bare.returncode != 0 and "needs BRIDGE_RATINGS" in bare.stdout  # no default
    if target == "hd":
        # OpenHaptics' tarball puts libHD.so.3.0.0 in lib64 and runs ldconfig, which makes
        # the soname's link (libHD.so.3.0) only in the loader's own folders: the check says
        # so, and the how-to's step makes it
        lib64 = Path(var.split("=", 1)[1]) / "lib64"
        first = _make(*make, f"BRIDGE_RATINGS={RATINGS}")
        assert first.returncode != 0
        assert "libHD.so.3.0, which the bridge loads at run time" in first.stdout, first.stdout
        assert f"ldconfig -n {lib64}" in first.stdout
        subprocess.run(["ldconfig", "-n", str(lib64)], check=True)
    run = _make(*make, f"BRIDGE_RATINGS={RATINGS}")
    assert run.returncode == 0, run.stdout + run.stderr
    assert "every function and constant the bridge uses agrees" in run.stdout
    bridge = tmp_path / f"hlfw-{target}"
    for pace in ("2", "0.5"):  # slower is no more real than faster
        other = subprocess.run([str(bridge), "--speed", pace], capture_output=True,
                               text=True, timeout=30)
        assert other.returncode == 2 and "real time" in other.stderr, (pace, other.stderr)
    proc = subprocess.Popen([str(bridge)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    try:
        port = proc.stdout.readline().strip()
        assert port.startswith("/dev/"), proc.stderr.read()
        with SerialDevice(port) as dev:
            assert dev.info.firmware == f"hlfw-2.0 {target}"
            assert dev.info.servo_rate_hz == (4000.0 if target == "dhd" else 1000.0)
            assert not dev.info.accelerometer
            assert dev.info.current_limit == pytest.approx(0.4)  # BRIDGE_RATINGS's
            assert dev.info.encoder_resolution == pytest.approx(2e-6)  # the lab's, not 1 µm
            told = dev.info.max_force
    finally:
        proc.terminate()
        _, err = proc.communicate(timeout=30)
    # the start-up check read the rating as the clamp and HELLO_ACK do
    assert f"at most {told:.2f} N along the axis" in err, err
    assert ("zero force, forces off, closed" if target == "dhd"
            else "force output off, device disabled") in err


def test_an_sdk_without_dhdGetMaxForce_builds_against_the_models_force(tmp_path):
    """SDK 3.7.0 has no dhdGetMaxForce (3.17.5 has): check-sdk finds it absent, the bridge
    builds without calling it and checks the ratings against the model's nominal force."""
    sdk = dhd_sdk(tmp_path, _swap("double __SDK dhdGetMaxForce(char ID = -1);\n", ""))
    run = _make("dhd", f"DHD_SDK={sdk}", f"BRIDGE_RATINGS={RATINGS}", f"BRIDGE_OUT={tmp_path}")
    assert run.returncode == 0, run.stdout + run.stderr
    assert "dhdGetMaxForce absent" in run.stdout
    out = subprocess.run(["timeout", "-s", "INT", "2", str(tmp_path / "hlfw-dhd")],
                         capture_output=True, text=True, timeout=30)
    assert "within the omega.3's 12.00 N (the model's nominal force)" in out.stderr, out.stderr


def test_a_missing_prerequisite_is_named_with_what_provides_it(tmp_path):
    """The link's prerequisites are checked before the build and each missing one named
    with what to install (issue 52, problem 4): OpenHaptics' libHD without the Touch's
    driver library it needs, and libdrd without libusb-1.0's development files (hidden
    here in a private mount namespace: an overlay that whites them out)."""
    oh = _make("hd", f"OPENHAPTICS={openhaptics(tmp_path, driver=False)}",
               f"BRIDGE_RATINGS={RATINGS}", f"BRIDGE_OUT={tmp_path}")
    assert oh.returncode != 0
    assert "libPHANToMIO.so.4" in oh.stdout and "Touch device driver" in oh.stdout, oh.stdout
    if os.geteuid() != 0 or shutil.which("unshare") is None:
        pytest.skip("hiding libusb-1.0 needs root and unshare (CI has both)")
    libdir = Path("/usr/lib/x86_64-linux-gnu")
    upper, work = tmp_path / "upper", tmp_path / "work"
    upper.mkdir()
    work.mkdir()
    for name in ("libusb-1.0.so", "libusb-1.0.a"):
        os.mknod(upper / name, 0o600 | 0o020000, os.makedev(0, 0))  # an overlay's whiteout
    sdk = dhd_sdk(tmp_path)
    script = (f"mount -t overlay overlay -o lowerdir={libdir},upperdir={upper},workdir={work} "
              f"{libdir} && exec make --no-print-directory -C {FIRMWARE_DIR} dhd DHD_SDK={sdk} "
              f"BRIDGE_OUT={tmp_path} BRIDGE_RATINGS='{RATINGS}'")
    fd = subprocess.run(["unshare", "-m", "sh", "-c", script], capture_output=True, text=True,
                        timeout=300)
    assert fd.returncode != 0
    assert "libusb-1.0-0-dev" in fd.stdout, fd.stdout + fd.stderr
    assert not (tmp_path / "hlfw-dhd").exists()


def _lenient_cflags() -> str:
    """The Makefile's CFLAGS with a real device's loop allowed to be held up a minute, not
    5 ms (HL_OVERRUN_TICKS): a test about what the operator is asked cannot depend on a busy
    test machine keeping a servo deadline (the device fault it latches otherwise is
    tests/device/test_bridge_safety.py's subject)."""
    run = subprocess.run(["make", "-s", "--no-print-directory", "-C", str(FIRMWARE_DIR),
                          "--eval=hl-print-cflags: ; @echo $(CFLAGS)", "hl-print-cflags"],
                         capture_output=True, text=True, check=True)
    return f"CFLAGS={run.stdout.strip()} -DHL_OVERRUN_TICKS=240000u"


@pytest.mark.slow
def test_the_self_test_on_a_real_device_asks_the_operator_to_tap(fd_sdk, tmp_path):
    """A real device's bridge (`make dhd`, no simulated contact) under `hapticlab device
    selftest`, the test as its operator: it taps (HL_STUB_DHD_TAP_FILE: the stand-in's hand
    taps while the file exists) at every prompt and stops when told. All 13 pass and the
    command exits 0: the e-stop, watchdog and exit checks among them cut a force the
    device put out with the stylus held above the surface. The wait for a tap is long
    (120 s) and ends as soon as the contact comes, so a busy host that is slow to play the
    operator cannot turn a tapped check into "gave up waiting" (it once waited 4 s of wall
    time); gave up waiting is tests/device/test_selftest_operator.py's, in device time."""
    run = _make("dhd", f"DHD_SDK={fd_sdk}", f"BRIDGE_OUT={tmp_path}",
                f"BRIDGE_RATINGS={RATINGS}", _lenient_cflags())
    assert run.returncode == 0, run.stdout + run.stderr
    tap = tmp_path / "tapping"
    bridge = subprocess.Popen([str(tmp_path / "hlfw-dhd")], stdout=subprocess.PIPE,
                              stderr=subprocess.DEVNULL, text=True,
                              env={**os.environ, "HL_STUB_DHD_TAP_FILE": str(tap)})
    said = []
    try:
        port = bridge.stdout.readline().strip()
        assert port.startswith("/dev/")
        test = subprocess.Popen([sys.executable, "-m", "app", "device", "selftest",
                                 f"serial:{port}", "--tap-wait", "120"], stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True,
                                env={**os.environ, "COLUMNS": "300"})  # a row, one line
        for line in test.stderr:  # what the operator reads, and does
            said.append(line.rstrip("\n"))
            if "tap the stylus down onto the virtual surface now" in line:
                tap.touch()
            elif "stop tapping" in line:
                tap.unlink(missing_ok=True)
        out = test.stdout.read()
        code = test.wait(timeout=60)
    finally:
        bridge.terminate()
        bridge.communicate(timeout=30)
    text = "\n".join(said)
    assert code == 0, out + text
    assert ("8 checks the device does alone (info, estop, end_window, watchdog, ramp, "
            "zero_on_exit, play_force, bad_input); 5 need someone to tap the stylus "
            "(real_sample, spring_law, transient_scaling, saturation, window_length)") in text
    for name in ("real_sample", "spring_law", "transient_scaling", "saturation",
                 "window_length"):
        assert f"[{name}] tap the stylus down onto the virtual surface now" in text, text
    assert "[saturation] warning: a hard pulse is coming" in text, text
    assert sum("contact: window recorded" in line for line in said) == 5, text
    assert "gave up waiting" not in text, text
    assert "13 passed, 0 failed" in out, out
    for name, cut in (("estop", "N of played force"), ("watchdog", "N of played force"),
                      ("zero_on_exit", "after an exception while putting out")):
        row = [line for line in out.splitlines() if f"│ {name} " in line]
        assert len(row) == 1 and cut in row[0], out
