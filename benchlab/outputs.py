"""The one output rule of every command that writes a file (issue 30): a measurement is never lost or overwritten.

- An existing output is refused unless `--force`; `--force` replaces only a regular file, never a directory, a
  device, a FIFO, a socket or a symbolic link (whose target may lie anywhere).
- No command writes over a file it reads (the same file by any name), and none writes over a run file
  (root `schema = benchlab-run/1`) unless writing run files is its job and the user said `--force`.
- An output directory (`report --out DIR`) that holds files already is refused unless `--force`; with it, each
  file written into it follows the rules above.
- Every file is written beside its destination under a hidden temporary name and renamed into place when whole
  (`replacing`): a crash or a full disk leaves the old file or none, never half a file. A full disk is one line
  naming the file (OutputError, exit 1). A temporary file whose writer was killed (its process id is in the name)
  is removed by the next write of that destination (`remove_stale_partials`).

`check_output`/`check_output_dir` run before any work, so a refusal costs nothing; `replacing` checks again at
the moment of writing (a figure inside an output directory, a file that appeared meanwhile).
"""

from __future__ import annotations

import errno
import glob
import os
import re
import secrets
import stat
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

from benchlab.errors import InputError

#: errno values that mean the disk (or the process's file-size limit, RLIMIT_FSIZE) has no room for the file.
NO_SPACE_ERRNOS = frozenset({errno.ENOSPC, errno.EFBIG, errno.EDQUOT})
#: What HDF5 says instead of an errno when a write fails for want of space (h5py passes its text on).
NO_SPACE_TEXTS = ("No space left on device", "File too large", "Disk quota exceeded")
#: The HDF5 superblock's signature, at offset 0 or after a user block of 512, 1024, 2048, ... bytes.
HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
HDF5_OFFSETS = (0, 512, 1024, 2048, 4096)
#: What follows `.STEM.` in the name of a file `replacing` writes, before the destination's suffix.
PARTIAL_NAME = re.compile(r"(?P<pid>[0-9]{1,10})-[0-9a-f]{8}\.part")


class OutputError(Exception):
    """A file could not be written (a full disk): one line naming the file; the CLI exits 1."""


def is_no_space(exc: BaseException) -> bool:
    """Whether `exc` says the disk is full (or the file-size limit was reached), by errno or by HDF5's text."""
    if isinstance(exc, OutputError) or (isinstance(exc, OSError) and exc.errno in NO_SPACE_ERRNOS):
        return True
    return any(text in str(exc) for text in NO_SPACE_TEXTS)


def no_space(path: "str | os.PathLike[str]", what: str) -> OutputError:
    """The one-line full-disk error for `path`; `what` says what became of the file."""
    return OutputError(f"{path}: no space left on the device ({what})")


def _kind(mode: int) -> str | None:
    """What a file that is not a regular file is, for the message; None for a regular file."""
    for test, name in ((stat.S_ISLNK, "a symbolic link"), (stat.S_ISDIR, "a directory"),
                       (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                       (stat.S_ISFIFO, "a FIFO"), (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return name
    return None if stat.S_ISREG(mode) else "not a regular file"


def is_run_file(path: "str | os.PathLike[str]") -> bool:
    """Whether the regular file `path` is a run file: HDF5 with root attribute `schema = benchlab-run/1`."""
    try:
        with open(path, "rb") as f:
            head = f.read(HDF5_OFFSETS[-1] + len(HDF5_SIGNATURE))
    except OSError:
        return False
    if not any(head[at:at + len(HDF5_SIGNATURE)] == HDF5_SIGNATURE for at in HDF5_OFFSETS):
        return False
    from benchlab.runfile.read import stored_schema

    return stored_schema(path) is not None


def _same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def check_target(path: "str | os.PathLike[str]", option: str, force: bool,
                 inputs: Sequence[str | os.PathLike[str]] = (), run_file: bool = False, hint: str = "") -> Path:
    """`path` if the rule lets it be written; else InputError naming the path and `option` (e.g. "--out").

    `inputs`: files the command reads (never written over); `run_file`: writing run files is the command's job;
    `hint`: what else the user may mean where the file exists (`run`: "--resume to continue it")."""
    hint = f"{hint}, " if hint else ""
    path = Path(path)
    for source in inputs:
        if _same_file(path, Path(source)):
            raise InputError(path, option, f"a file other than the run file or other input it reads ({source}): a "
                                           "command never writes over its input")
    try:
        mode = os.lstat(path).st_mode
    except FileNotFoundError:
        return path
    kind = _kind(mode)
    if kind is not None:
        raise InputError(path, option, f"a new file or, with --force, a regular file to replace (it is {kind})")
    if is_run_file(path) and not (run_file and force):
        raise InputError(path, option, f"a new file ({hint}--force to replace it)" if run_file else
                         "a file of another name: this one is a run file, a measurement never written over")
    if not force:
        raise InputError(path, option, f"a new file (it exists: {hint}--force to replace it)")
    return path


def check_output(path: "str | os.PathLike[str]", option: str, force: bool,
                 inputs: Sequence[str | os.PathLike[str]] = (), run_file: bool = False, hint: str = "") -> Path:
    """check_target for a file given on the command line, whose directory must exist."""
    path = Path(path)
    if not path.parent.is_dir():
        raise InputError(path, option, f"a file in an existing directory ({path.parent} not found)")
    return check_target(path, option, force, inputs, run_file, hint)


def _paths(value: object) -> list[str]:
    """The paths an argument's value names (a text or path, or a list of them), as given."""
    values = value if isinstance(value, (list, tuple)) else [value]
    return [os.fspath(v) for v in values if isinstance(v, (str, os.PathLike)) and os.fspath(v)]


def _names_one_file(a: Path, b: Path) -> bool:
    """Whether two paths name one file: the same file by any name, or the same place where one does not exist."""
    return _same_file(a, b) or a.resolve() == b.resolve()


def check_log(path: "str | os.PathLike[str]", arguments: dict[str, object], force: bool, resume: bool) -> Path:
    """The `--log` file if the rule lets it be written: a regular file (never a link, device or FIFO), never a run
    file, never a file any other argument names (an input the command reads, its `--out`); an existing log only
    with `--force` (replaced) or when resuming (appended to: the run's log goes on)."""
    path = Path(path)
    for option, value in arguments.items():
        for other in _paths(value):
            if _names_one_file(path, Path(other)):
                raise InputError(path, "--log", f"a file of its own (it is also the command's {option}: {other})")
    return check_output(path, "--log", force or resume)


def check_output_dir(path: "str | os.PathLike[str]", option: str, force: bool) -> Path:
    """The output directory if it may be written (the command creates it where missing; its parent must exist): one
    that holds files already needs `force`, and a file or anything else by that name is refused."""
    path = Path(path)
    try:
        mode = os.lstat(path).st_mode
    except FileNotFoundError:
        if not path.parent.is_dir():
            raise InputError(path, option, f"a directory in an existing folder ({path.parent} not found)") from None
        return path
    if not stat.S_ISDIR(mode):
        raise InputError(path, option, f"a directory (it is {_kind(mode) or 'a file'})")
    if not force and any(path.iterdir()):
        raise InputError(path, option, "a new or empty directory (it holds files: --force to replace the ones "
                                       "this command writes)")
    return path


@contextmanager
def replacing(path: "str | os.PathLike[str]", run_file: bool = False) -> Iterator[Path]:
    """A temporary path beside `path` to write the whole output to; renamed onto `path` when the block ends without
    an error, removed otherwise. The target is checked again (check_target with force): a directory, device, link,
    or a run file where `run_file` is False, is never replaced. A full disk is OutputError (one line)."""
    path = Path(path)
    check_target(path, "output", force=True, run_file=run_file)
    remove_stale_partials(path)
    tmp = path.with_name(f".{path.stem}.{os.getpid()}-{secrets.token_hex(4)}.part{path.suffix}")
    try:
        yield tmp
        os.replace(tmp, path)
    except Exception as exc:
        if is_no_space(exc):
            raise no_space(path, "nothing written, any earlier file kept") from None
        raise
    finally:
        tmp.unlink(missing_ok=True)


def _process_alive(pid: int) -> bool:
    """Whether a process `pid` exists on this machine (one of another user's counts as alive)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def remove_stale_partials(path: "str | os.PathLike[str]") -> list[Path]:
    """Remove the temporary files `replacing` left beside `path` (`.STEM.PID-TOKEN.partSUFFIX`) when their writer
    was killed (SIGKILL, a power cut): those whose process no longer exists. Returns what was removed."""
    path = Path(path)
    removed = []
    for partial in path.parent.glob(f".{glob.escape(path.stem)}.*.part{glob.escape(path.suffix)}"):
        match = PARTIAL_NAME.fullmatch(partial.name[len(path.stem) + 2:-len(path.suffix) or None])
        if match is None or _process_alive(int(match["pid"])):
            continue
        try:
            partial.unlink()
        except FileNotFoundError:  # another writer removed it first
            continue
        removed.append(partial)
    return removed


def write_text(path: "str | os.PathLike[str]", text: str) -> Path:
    """Write `text` to `path` whole (see replacing)."""
    path = Path(path)
    with replacing(path) as tmp:
        tmp.write_text(text)
    return path
