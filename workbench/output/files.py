"""Files: atomic writes, output paths checked before any work, names made safe for the file system.

Every file workbench writes (archives, checkpoints, figures, VTK) goes through
:func:`atomic_write`: the content is written to a hidden temporary file
``.NAME.PID.RANDOM.tmp`` in the target folder and renamed over the target, so a
reader never sees half a file and a kill leaves the previous file intact. The
temporary files of processes that died before their rename are removed by the
next write to the same target. Written files get the usual permissions (0666
less the umask), as any other file the user creates.

Examples
--------
>>> import tempfile, pathlib
>>> p = atomic_write(pathlib.Path(tempfile.mkdtemp()) / "a.txt", lambda tmp: tmp.write_text("hello"))
>>> p.read_text()
'hello'
>>> safe_name("../../x y$")
'x_y_'
"""
from __future__ import annotations

import errno
import hashlib
import os
import re
import secrets
from pathlib import Path

from ..errors import Unwritable


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, another user's
        return True
    return True


#: A temporary without a writer's pid (as older versions named them) is stale after this many seconds.
LEGACY_STALE = 600.0


def remove_stale_temporaries(path: Path) -> list:
    """Remove the temporaries of ``path`` that no writer will finish; return them.

    ``.NAME.PID.HEX.tmp`` whose process is gone, and ``.NAME.XXXXXXXX.tmp`` (no pid: older
    versions' names) older than :data:`LEGACY_STALE` seconds.
    """
    import time

    path = Path(path)
    removed = []
    with_pid = re.compile(re.escape(f".{_stem(path)}.") + r"(\d+)\.[0-9a-f]+\.tmp$")
    legacy = re.compile(re.escape(f".{path.name}.") + r"[A-Za-z0-9_]{8}\.tmp$")
    try:
        entries = list(path.parent.iterdir())
    except OSError:
        return removed
    now = time.time()
    for entry in entries:
        m = with_pid.match(entry.name)
        stale = m is not None and int(m.group(1)) != os.getpid() and not _alive(int(m.group(1)))
        if m is None and legacy.match(entry.name):
            try:
                stale = now - entry.stat().st_mtime > LEGACY_STALE
            except OSError:
                stale = False
        if stale:
            try:
                entry.unlink()
                removed.append(entry)
            except OSError:
                pass
    return removed


def _stem(path: Path) -> str:
    """The target's part of its temporary's name: its name, or where that would make the temporary longer than the
    255 bytes a file system allows, a digest of it (an ``-o`` of 236-255 bytes passed the check before the run and
    failed at its end, found by an outside pass)."""
    name = path.name
    if len(os.fsencode(name)) <= 200:
        return name
    return "long-name-" + hashlib.sha256(os.fsencode(name)).hexdigest()[:16]


def atomic_write(path, writer) -> Path:
    """Write ``path`` atomically: ``writer(tmp_path)`` fills a temporary file that is then renamed.

    Never replaces what is not a regular file (a device, a pipe, a socket: the rename would put a file in its
    place) and raises OSError naming ``path`` for any failure, also a library's that is not an OSError (netCDF
    reports a full disk as RuntimeError). A leading ``~`` is the home folder, as xarray and matplotlib read it (taken
    as a folder named ``~``, the temporary went to the home folder through xarray and was left there)."""
    path = Path(path).expanduser()
    if path.is_symlink():  # (written through the link, as the shell's ``>`` does: it was replaced by a file, its
        try:  # target keeping the old content, found by an outside pass)
            path = path.resolve()
        except (OSError, RuntimeError):  # (a loop of links)
            raise OSError(errno.ELOOP, "it is a symbolic link that loops", str(path)) from None
    if path.exists() and not path.is_file() and not path.is_dir():
        raise OSError(errno.EEXIST, "it exists and is not a regular file (a device, a pipe or a socket): it is not "
                                    "replaced", str(path))
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise OSError(err.errno, f"its folder cannot be made ({err.strerror or err})", str(path)) from None
    remove_stale_temporaries(path)
    tmp = path.parent / f".{_stem(path)}.{os.getpid()}.{secrets.token_hex(4)}.tmp"
    try:
        writer(tmp)
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    except (OSError, RuntimeError, ValueError) as err:  # (netCDF4: RuntimeError "NetCDF: HDF error" on a full disk)
        tmp.unlink(missing_ok=True)
        said = str(err).splitlines()[0] if str(err) else type(err).__name__
        if isinstance(err, OSError):
            raise OSError(err.errno or errno.EIO, (err.strerror or said) + _limits(path.parent), str(path)) from None
        raise OSError(errno.EIO, said + _limits(path.parent), str(path)) from None
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def _limits(folder: Path) -> str:
    """What may have stopped a write, said beside the library's words: netCDF reports a full disk as "NetCDF: HDF
    error" or "Permission denied", and a file size limit (``ulimit -f``, which makes a write fail with EFBIG) the
    same way (found by an outside pass)."""
    import shutil

    said = []
    try:
        import resource

        soft = resource.getrlimit(resource.RLIMIT_FSIZE)[0]
        if soft != resource.RLIM_INFINITY:
            said.append(f"files are limited to {soft / 1e6:.3g} MB here by ulimit -f")
    except (ImportError, OSError, ValueError):  # (no resource module: Windows)
        pass
    try:
        free = shutil.disk_usage(folder).free
        if free < 100e6:
            said.append(f"its disk has {free / 1e6:.3g} MB free")
    except OSError:
        pass
    return "".join(f"; {s}" for s in said)


def check_output(path, option: str, *, folder: bool = False) -> Path:
    """Refuse, before any work, an output path that cannot be written: an existing directory where a file is
    meant (or a file where a folder is meant), a parent that is a file, a folder without write permission."""
    if str(path).strip() == "":
        raise Unwritable(f"{option} '': give a {'folder' if folder else 'file'} name")
    from ..values import check_utf8_path

    check_utf8_path(path, option)
    path = Path(path).expanduser()
    longest = max((len(part.encode()) for part in path.parts), default=0)
    if longest > 255:
        raise Unwritable(f"{option} {str(path)[:60]!r}...: a name in it is {longest} bytes long, more than the 255 "
                             "a file system allows")
    whole = len(os.fsencode(os.path.abspath(path)))
    if whole >= 4096:  # (PATH_MAX on Linux: the temporary beside it would not open)
        raise Unwritable(f"{option} {str(path)[:60]!r}...: the path is {whole} bytes long, more than the 4095 a "
                             "file system allows")
    if path.is_symlink():
        try:
            path.resolve(strict=False)
        except (OSError, RuntimeError):
            raise Unwritable(f"{option} {str(path)!r} is a symbolic link that loops; give a file name") from None
    if path.exists() and not path.is_file() and not path.is_dir():
        raise Unwritable(f"{option} {str(path)!r} exists and is not a regular file (a device, a pipe or a socket); "
                             "give a file name")
    if folder:
        if path.exists() and not path.is_dir():
            raise Unwritable(f"{option} {str(path)!r} is a file; give a folder for the files")
        target = path
    else:
        if path.is_dir():
            raise Unwritable(f"{option} {str(path)!r} is a directory; give a file name, e.g. {str(path / 'out')}")
        target = path.parent
    existing = target
    while not existing.exists():
        if existing.parent == existing:
            break
        existing = existing.parent
    if existing.exists() and not existing.is_dir():
        raise Unwritable(f"{option} {str(path)!r}: {str(existing)!r} is a file, not a folder")
    if existing.exists() and (not os.access(existing, os.W_OK | os.X_OK) or _virtual(existing)):
        raise Unwritable(f"{option} {str(path)!r}: no permission to write in {str(existing)!r}")
    return path


def _virtual(folder: Path) -> bool:
    """Whether ``folder`` is on a kernel's virtual file system (/proc, /sys), where no file can be made even as root."""
    try:
        resolved = folder.resolve()
    except OSError:
        return False
    return resolved.parts[1:2] in (("proc",), ("sys",))


def safe_name(name: str) -> str:
    """A scene name as a file name: path separators and anything but letters, digits, '.', '-', '_' replaced."""
    base = str(name).replace("\\", "/").split("/")[-1]
    text = re.sub(r"[^A-Za-z0-9._-]+", "_", base).strip(".")
    return text or "run"
