"""Checking a submission zip, and unpacking its wheels, without trusting a byte of either.

Standard library only, and no import of this project: the service runs this file inside the
sandbox (no network, capped memory, CPU time, file sizes; ``evaluator/validation.py``), so a
participant's bytes are inflated, extracted and compiled there, never in the API or on a
worker's host. Participants' local checks (``arena submission check``) import the same functions.

Every rule has a short name carried by :class:`Rejected` with the entry at fault
(``docs/submissions.md`` lists them). Two levels:

- :func:`check_directory`: what the zip's central directory alone tells (entry count, names,
  kinds, declared sizes and compression ratios). Cheap: the API runs it on the upload.
- :func:`check_submission`: everything else: extraction (counting bytes again in case an entry
  lies about its size), nested archives (streamed from disk, never read whole into memory, and
  counted against the same budget), ``policy.py`` and ``train.py`` compiled, and the files that
  configure the submission read and parsed (``agent.yaml``, ``requirements.txt``,
  ``explanation.md``): the host receives their bounded, flat result in the verdict and opens none
  of them.

Run as a program (``python3 intake.py MODE INPUT OUTPUT``) it writes its verdict to
``OUTPUT/report.json``: ``{"ok": true, ...}`` or ``{"ok": false, "entry", "rule", "message"}``.
"""

from __future__ import annotations

import ast
import bz2
import json
import lzma
import os
import re
import shutil
import stat
import sys
import zipfile
import zlib
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

ARCHIVE = "<zip>"
POLICY = "policy.py"
TRAIN_SCRIPT = "train.py"
AGENT_YAML = "agent.yaml"
REQUIREMENTS = "requirements.txt"
EXPLANATION = "explanation.md"
SMARTS_CONFIG = "config.yaml"
# A configuration file is small: a bigger one is refused before it is parsed.
MAX_CONFIG_BYTES = 64 * 1024
# The explanation is shown on a web page; the rest of a long file is cut.
MAX_EXPLANATION_CHARS = 20_000
# agent.yaml is a flat mapping of a few options: what the host accepts of it is bounded too.
MAX_OPTIONS = 64
MAX_OPTION_NAME = 64
MAX_OPTION_VALUE = 256
# A requirement line the host parses (packaging's parser recurses into parentheses: 20,000 deep
# raised RecursionError in the worker): bounded here, where the team's bytes are read.
MAX_REQUIREMENT_CHARS = 1000
MAX_REQUIREMENT_NESTING = 8
REPORT = "report.json"
LIMITS = "limits.json"
SUBMISSION_DIR = "submission"
DEPS_DIR = "deps"
UPLOAD = "upload.zip"
WHEELS_DIR = "wheels"
# What the Python files import, for the porting notes (submissions/intake/porting.py): written
# beside the verdict, also when the scripts are rejected, so a rejected port still gets them.
PORTING = "porting.json"
MAX_SCANNED_FILES = 500
MAX_SCANNED_BYTES = 1024**2
# All scanned files together: parsing is the validation's time, which the team's budget pays
# (500 files of 1 MiB once kept a validation busy for its whole 300 s).
MAX_SCANNED_TOTAL_BYTES = 8 * 1024**2
MAX_SCANNED_NAMES = 1000
MAX_MODULE_NAME = 200
# The packages agent_runtime/compat provides for observation_format: smarts2022: each name a
# submission takes from them is listed with its place (the host checks it against the package).
COMPAT_PACKAGES = ("smarts", "gym")
MAX_COMPAT_USES = 2000
# numpy's aliases of Python types, removed in numpy 1.24 -> the Python type to use instead.
NUMPY_ALIASES = {
    "float": "float",
    "int": "int",
    "bool": "bool",
    "object": "object",
    "str": "str",
    "long": "int",
    "unicode": "str",
    "complex": "complex",
}
# Ratios are judged only above this size: small files of padding compress absurdly well.
RATIO_FLOOR_BYTES = 1024**2
# In a wheel, one entry's ratio only above this size: a repaired wheel's shared library is padded
# to the 2 MiB page alignment (Pillow's libXau: 2 MiB, 224:1); the wheel's whole ratio and the
# requirements' byte caps bound what its small entries add up to.
WHEEL_ENTRY_RATIO_FLOOR_BYTES = 16 * 1024**2
# A nested archive inside a nested archive inside the submission is as deep as we look.
MAX_NESTING = 2
COPY_CHUNK = 1024**2
STREAM_MAGIC = {
    b"\x1f\x8b": "gzip",
    b"BZh": "bzip2",
    b"\xfd7zXZ\x00": "xz",
}
ZIP_MAGIC = b"PK\x03\x04"
# Linux's limits: a longer name cannot be written, so it is refused before extraction.
MAX_NAME_PART_BYTES = 255
MAX_NAME_BYTES = 1024
# What one central-directory record may take beyond its fixed 46 bytes and name (extra fields,
# comment): zipfile holds every record in memory, so the directory is bounded before it is read.
DIRECTORY_SLACK_BYTES = 1024
DIRECTORY_RECORD = 46 + MAX_NAME_BYTES + DIRECTORY_SLACK_BYTES
# What reading a damaged entry raises: a bad CRC, a truncated or corrupt deflate stream, a
# compression method Python lacks.
CORRUPT_ENTRY_ERRORS = (
    zipfile.BadZipFile,
    zlib.error,
    lzma.LZMAError,
    EOFError,
    NotImplementedError,
)
UNIX_CREATE_SYSTEM = 3


class Rejected(Exception):
    """A rule the zip breaks: ``entry`` at fault (``"<zip>"`` for the whole), ``rule``'s name."""

    def __init__(self, entry: str, rule: str, message: str) -> None:
        super().__init__(f"{entry}: {message} [rule: {rule}]")
        self.entry = entry
        self.rule = rule
        self.message = message


@dataclass(frozen=True)
class Limits:
    max_zip_bytes: int
    max_unzipped_bytes: int
    max_entries: int
    max_compression_ratio: float
    # Requirements: one wheel (its file), and every wheel together, unpacked.
    max_deps_bytes: int = 0
    max_deps_files: int = 0
    max_wheel_bytes: int = 0


class Budget:
    """What is left of the entry and byte limits while archives are read (nested ones too)."""

    def __init__(self, entries: int, size: int, what: str = "") -> None:
        self.max_entries = self.entries = entries
        self.max_bytes = self.bytes = size
        self.what = what or "nested archives included"

    def take_entry(self, name: str) -> None:
        self.entries -= 1
        if self.entries < 0:
            raise Rejected(
                name, "max-entries", f"more than {self.max_entries} entries ({self.what})"
            )

    def take_bytes(self, name: str, size: int) -> None:
        self.bytes -= size
        if self.bytes < 0:
            limit = self.max_bytes / 1024**2
            raise Rejected(
                name, "max-unzipped-bytes", f"more than {limit:g} MiB uncompressed ({self.what})"
            )


def submission_budget(limits: Limits) -> Budget:
    return Budget(limits.max_entries, limits.max_unzipped_bytes)


def open_zip(
    path: Path, limits: Limits, shown: str = ARCHIVE, size_rule: str = "max-zip-bytes"
) -> zipfile.ZipFile:
    """The zip at ``path``, once its end record says the directory is within the limits (its
    own size: the upload's cap, or with ``size_rule="max-wheel-bytes"`` one wheel's)."""
    size = path.stat().st_size
    if size == 0:
        raise Rejected(shown, "empty-file", "the upload is an empty file, not a zip")
    cap = limits.max_wheel_bytes if size_rule == "max-wheel-bytes" else limits.max_zip_bytes
    if size > cap:
        raise Rejected(shown, size_rule, f"the zip is larger than {cap / 1024**2:g} MiB")
    try:
        with path.open("rb") as handle:
            # The end record, read before zipfile parses (and holds) every directory record.
            end = zipfile._EndRecData(handle)
    except OSError as error:
        raise Rejected(shown, "not-a-zip", f"the upload is not a readable zip ({error})") from error
    if end is None:
        raise Rejected(shown, "not-a-zip", "the upload is not a readable zip (no end record)")
    entries, directory_bytes = end[zipfile._ECD_ENTRIES_TOTAL], end[zipfile._ECD_SIZE]
    # Past the entry limit by far: refused before its directory is parsed (just past it, the
    # directory check names the first entry too many).
    if entries > 2 * limits.max_entries:
        raise Rejected(shown, "max-entries", f"more than {limits.max_entries} entries")
    if directory_bytes > min(max(entries, 1), 2 * limits.max_entries) * DIRECTORY_RECORD:
        raise Rejected(
            shown,
            "central-directory",
            f"the zip's directory ({directory_bytes} bytes for {entries} entries) is larger "
            "than its entries can need",
        )
    try:
        return zipfile.ZipFile(path)
    except (zipfile.BadZipFile, zipfile.LargeZipFile, OSError, ValueError) as error:
        raise Rejected(shown, "not-a-zip", f"the upload is not a readable zip ({error})") from error


def entry_path(info: zipfile.ZipInfo) -> PurePosixPath:
    """The entry's relative path, or Rejected for names that could escape the folder."""
    name = info.filename
    # zipfile cuts a name at its first NUL (``filename``); the name as stored is ``orig_filename``.
    stored = info.orig_filename
    if not name or "\0" in stored or any(ord(c) < 32 or ord(c) == 127 for c in stored):
        raise Rejected(
            repr(stored), "bad-name", "an entry's name is empty or holds a NUL or control character"
        )
    if name.startswith(("/", "\\")) or (len(name) > 1 and name[1] == ":"):
        raise Rejected(name, "absolute-path", "absolute paths are not allowed in the zip")
    parts = PurePosixPath(name.replace("\\", "/")).parts
    if ".." in parts:
        raise Rejected(name, "zip-slip", "'..' in an entry name would write outside the folder")
    if not parts or parts == (".",):
        raise Rejected(name, "bad-name", "an entry name points at the folder itself")
    longest = max(len(part.encode()) for part in parts)
    if longest > MAX_NAME_PART_BYTES or len(name.encode()) > MAX_NAME_BYTES:
        raise Rejected(
            name[:80] + ("..." if len(name) > 80 else ""),
            "name-too-long",
            f"a file or folder name is over {MAX_NAME_PART_BYTES} bytes, or the path over "
            f"{MAX_NAME_BYTES}",
        )
    return PurePosixPath(*parts)


def check_kind(info: zipfile.ZipInfo, shown: str) -> None:
    if info.flag_bits & 0x1:
        raise Rejected(shown, "encrypted", "encrypted entries cannot be read")
    # Only Unix-made zips carry a file type in the high attribute bits, and many tools (Python's
    # own ZipFile.writestr among them) write permission bits with no type: that is a plain file.
    if info.create_system != UNIX_CREATE_SYSTEM:
        return
    kind = stat.S_IFMT(info.external_attr >> 16)
    if kind == stat.S_IFLNK:
        raise Rejected(shown, "symlink", "symbolic links are not allowed")
    if kind not in (0, stat.S_IFREG, stat.S_IFDIR):
        raise Rejected(shown, "special-file", "device files, fifos and sockets are not allowed")


def check_ratio(
    info: zipfile.ZipInfo, limits: Limits, shown: str, floor: int = RATIO_FLOOR_BYTES
) -> None:
    if info.file_size <= floor:
        return
    ratio = info.file_size / max(info.compress_size, 1)
    if ratio > limits.max_compression_ratio:
        raise Rejected(
            shown,
            "compression-ratio",
            f"compresses {ratio:.0f}:1 (limit {limits.max_compression_ratio:g}:1): a zip bomb?",
        )


def check_directory(
    archive: zipfile.ZipFile,
    limits: Limits,
    budget: Budget,
    prefix: str = "",
    ratio_floor: int = RATIO_FLOOR_BYTES,
) -> None:
    """Every rule the central directory alone can judge; no entry's data is read."""
    seen: set[PurePosixPath] = set()
    files: set[PurePosixPath] = set()
    folders: set[PurePosixPath] = set()
    for info in archive.infolist():
        shown = f"{prefix}{info.filename}"
        budget.take_entry(shown)
        path = entry_path(info)
        if path in seen:
            raise Rejected(shown, "duplicate-entry", "the same name appears twice")
        seen.add(path)
        check_kind(info, shown)
        # A file `a` beside a folder `a/` (or an entry `a/b`) cannot both be written.
        parents = set(path.parents) - {PurePosixPath(".")}
        if parents & files or (not info.is_dir() and path in folders):
            raise Rejected(shown, "file-folder-clash", "a name is both a file and a folder")
        folders |= parents | ({path} if info.is_dir() else set())
        if info.is_dir():
            continue
        files.add(path)
        check_ratio(info, limits, shown, ratio_floor)
        budget.take_bytes(shown, info.file_size)


def _read_chunk(handle, shown: str) -> bytes:
    try:
        return handle.read(COPY_CHUNK)
    except CORRUPT_ENTRY_ERRORS as error:
        raise Rejected(shown, "corrupt-entry", f"cannot be read: {error}") from error


def copy_entry(archive: zipfile.ZipFile, info: zipfile.ZipInfo, target: Path, shown: str) -> None:
    """Stream one entry to ``target``, refusing more bytes than it declares."""
    try:
        source = archive.open(info)
    except CORRUPT_ENTRY_ERRORS as error:
        raise Rejected(shown, "corrupt-entry", f"cannot be read: {error}") from error
    with source, target.open("xb") as sink:
        written = 0
        while chunk := _read_chunk(source, shown):
            written += len(chunk)
            if written > info.file_size:
                raise Rejected(shown, "size-mismatch", "the entry holds more than it declares")
            sink.write(chunk)


def extract(archive: zipfile.ZipFile, dest: Path, prefix: str = "") -> list[Path]:
    """Write the (checked) entries under ``dest``; returns the files written."""
    dest.mkdir(parents=True, exist_ok=True)
    written = []
    for info in archive.infolist():
        target = dest.joinpath(*entry_path(info).parts)
        if info.is_dir():
            target.mkdir(parents=True, exist_ok=True)
            continue
        target.parent.mkdir(parents=True, exist_ok=True)
        copy_entry(archive, info, target, f"{prefix}{info.filename}")
        written.append(target)
    return written


def archive_kind(head: bytes) -> str | None:
    if head.startswith(ZIP_MAGIC):
        return "zip"
    return next((kind for magic, kind in STREAM_MAGIC.items() if head.startswith(magic)), None)


def check_nested_file(
    path: Path, shown: str, limits: Limits, budget: Budget, depth: int, scratch: Path
) -> None:
    """A nested archive's contents count against the budget, whatever its name says. Read from
    disk: a nested zip in a nested zip is streamed to ``scratch`` first, never held in memory."""
    with path.open("rb") as handle:
        kind = archive_kind(handle.read(8))
    if kind is None:
        return
    if depth >= MAX_NESTING:
        raise Rejected(shown, "nested-archive", f"archives nested more than {MAX_NESTING} deep")
    if kind != "zip":
        with path.open("rb") as handle:
            budget.take_bytes(f"{shown} (inflated)", inflated_size(handle, kind, budget.bytes))
        return
    try:
        nested = zipfile.ZipFile(path)
    except (zipfile.BadZipFile, zipfile.LargeZipFile, ValueError):
        return  # not a zip after all: a file like any other
    with nested:
        check_directory(nested, limits, budget, prefix=f"{shown}!")
        for info in nested.infolist():
            if info.is_dir():
                continue
            inner = f"{shown}!{info.filename}"
            scratch.mkdir(parents=True, exist_ok=True)
            copy = scratch / f"nested-{depth}"
            copy.unlink(missing_ok=True)
            copy_entry(nested, info, copy, inner)
            try:
                check_nested_file(copy, inner, limits, budget, depth + 1, scratch)
            finally:
                copy.unlink(missing_ok=True)


def inflated_size(handle, kind: str, cap: int) -> int:
    """Bytes a gzip/bzip2/xz stream inflates to, counting no further than just past ``cap``."""
    decompressor = {
        "gzip": lambda: zlib.decompressobj(16 + zlib.MAX_WBITS),
        "bzip2": bz2.BZ2Decompressor,
        "xz": lzma.LZMADecompressor,
    }[kind]()
    produced = 0
    while (chunk := handle.read(COPY_CHUNK)) and not decompressor.eof:
        pending = chunk
        while True:
            try:
                produced += len(decompressor.decompress(pending, COPY_CHUNK))
            except (zlib.error, OSError, EOFError, lzma.LZMAError):
                return produced
            if produced > cap or decompressor.eof:
                return produced
            if kind == "gzip":
                pending = decompressor.unconsumed_tail
                if not pending:
                    break
            else:
                pending = b""
                if decompressor.needs_input:
                    break
    return produced


def read_script(root: Path, name: str) -> str | None:
    path = root / name
    if not path.is_file():
        return None
    try:
        return path.read_bytes().decode("utf-8-sig")
    except UnicodeDecodeError as error:
        raise Rejected(name, "not-utf8", f"is not UTF-8 text ({error})") from error


def parse_script(name: str, source: str, rule: str) -> ast.Module:
    """The syntax tree of a submission's script; its rules are ``<rule>-syntax`` and
    ``<rule>-too-deep``."""
    try:
        tree = compile(source, name, "exec", flags=ast.PyCF_ONLY_AST, dont_inherit=True)
        compile(tree, name, "exec", dont_inherit=True)
    except SyntaxError as error:
        where = f"line {error.lineno}" + (f", column {error.offset}" if error.offset else "")
        raise Rejected(name, f"{rule}-syntax", f"{error.msg} ({where})") from error
    except ValueError as error:
        raise Rejected(name, f"{rule}-syntax", str(error)) from error
    except (RecursionError, MemoryError) as error:
        # A deeply nested expression overflows the compiler's stack (CPython raises either), or
        # the script is too big for the intake's memory: not a program we can check.
        raise Rejected(
            name,
            f"{rule}-too-deep",
            f"nests expressions too deeply, or is too large, to compile ({type(error).__name__})",
        ) from error
    return tree


def top_level_names(tree: ast.Module) -> list[str]:
    """Names a module defines at its top level: classes, functions, assignments, imports."""
    names = []
    for node in tree.body:
        if isinstance(node, ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
            names.append(node.name)
        elif isinstance(node, ast.Assign | ast.AnnAssign):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            names += [t.id for t in targets if isinstance(t, ast.Name)]
        elif isinstance(node, ast.ImportFrom | ast.Import):
            names += [(alias.asname or alias.name).split(".")[0] for alias in node.names]
    return names


def scan_sources(root: Path) -> dict:
    """Modules the submission's Python files import, numpy aliases they use and whether
    ``policy.py`` defines ``submitted_wrappers`` (syntax trees only; a file that does not parse,
    is past the size cap, the file count or the total size is skipped: the notes are advice, not
    rules)."""
    imports: set[str] = set()
    aliases: set[str] = set()
    compat_uses: list[list] = []
    defines_wrappers = False
    sources = sorted(
        path for path in root.rglob("*.py") if path.is_file() and not path.is_symlink()
    )
    # policy.py first: its notes matter most when the total cap cuts the scan short.
    sources.sort(key=lambda path: path != root / POLICY)
    scanned = 0
    for path in sources[:MAX_SCANNED_FILES]:
        size = path.stat().st_size
        if size > MAX_SCANNED_BYTES or scanned + size > MAX_SCANNED_TOTAL_BYTES:
            continue
        scanned += size
        try:
            tree = ast.parse(path.read_bytes())
        except (SyntaxError, ValueError, RecursionError, MemoryError):
            continue  # check_scripts names what is wrong with policy.py; others are not ours
        if path == root / POLICY:
            defines_wrappers = any(
                isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef)
                and node.name == "submitted_wrappers"
                for node in tree.body
            )
        numpy_names = {"numpy"}
        nodes = list(ast.walk(tree))
        if len(compat_uses) < MAX_COMPAT_USES:
            where = str(path.relative_to(root))[:MAX_MODULE_NAME]
            compat_uses += compat_names(tree, nodes, where)[: MAX_COMPAT_USES - len(compat_uses)]
        for node in nodes:
            if isinstance(node, ast.Import):
                for alias in node.names:
                    imports.add(alias.name)
                    if alias.name == "numpy":
                        numpy_names.add(alias.asname or "numpy")
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                imports.add(node.module)
        for node in nodes:
            if (
                isinstance(node, ast.Attribute)
                and node.attr in NUMPY_ALIASES
                and isinstance(node.value, ast.Name)
                and node.value.id in numpy_names
            ):
                aliases.add(node.attr)
        del tree, nodes
    modules = (
        m
        for m in imports
        if len(m) <= MAX_MODULE_NAME and all(part.isidentifier() for part in m.split("."))
    )
    return {
        "imports": sorted(modules)[:MAX_SCANNED_NAMES],
        "numpy_aliases": sorted(aliases),
        "defines_wrappers": defines_wrappers,
        "compat_uses": compat_uses,
        "ships_packages": [name for name in COMPAT_PACKAGES if _ships(root, name)],
    }


def _ships(root: Path, package: str) -> bool:
    """Whether the submission holds its own ``package`` (it comes first on ``sys.path``)."""
    return (root / package / "__init__.py").is_file() or (root / f"{package}.py").is_file()


def _guarded(tree: ast.Module) -> set[int]:
    """The ids of the nodes inside a ``try`` that catches ImportError (or any exception)."""
    catches = {"ImportError", "ModuleNotFoundError", "Exception", "BaseException"}
    inside: set[int] = set()
    for node in ast.walk(tree):
        if not isinstance(node, ast.Try):
            continue
        caught = set()
        for handler in node.handlers:
            kinds = handler.type.elts if isinstance(handler.type, ast.Tuple) else [handler.type]
            caught |= {k.id if isinstance(k, ast.Name) else "" for k in kinds if k is not None}
            if handler.type is None:
                caught.add("BaseException")
        if caught & catches:
            inside |= {id(n) for statement in node.body for n in ast.walk(statement)}
    return inside


def _dotted(node: ast.AST) -> list[str] | None:
    """``a.b.c`` as ``["a", "b", "c"]`` (None for anything but names and attributes)."""
    parts = []
    while isinstance(node, ast.Attribute):
        parts.append(node.attr)
        node = node.value
    if not isinstance(node, ast.Name):
        return None
    return [node.id, *reversed(parts)]


def compat_names(tree: ast.Module, nodes: list[ast.AST], where: str) -> list[list]:
    """What a file takes from :data:`COMPAT_PACKAGES`, as ``[file, line, dotted path, guarded]``:
    each ``import smarts.a.b`` (the module's path), each ``from smarts.a import X``
    (``smarts.a.X``), and each attribute read through a name bound to such a module
    (``m.X`` after ``import smarts.a as m``: ``smarts.a.X``; ``smarts.a.X.y`` after ``import
    smarts``). Which of these the package has is the host's question: it knows the package."""
    guarded = _guarded(tree)
    bound: dict[str, str] = {}  # local name -> the dotted path it stands for
    uses = []

    def use(node: ast.AST, path: str) -> None:
        if len(path) <= MAX_MODULE_NAME:
            uses.append([where, getattr(node, "lineno", 0), path, id(node) in guarded])

    for node in nodes:
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] in COMPAT_PACKAGES:
                    use(node, alias.name)
                    local = alias.asname or alias.name.split(".")[0]
                    bound[local] = alias.name if alias.asname else local
        elif (
            isinstance(node, ast.ImportFrom)
            and node.level == 0
            and (node.module or "").split(".")[0] in COMPAT_PACKAGES
        ):
            for alias in node.names:
                if alias.name != "*":
                    use(node, f"{node.module}.{alias.name}")
                    bound[alias.asname or alias.name] = f"{node.module}.{alias.name}"
    for node in nodes:
        if not isinstance(node, ast.Attribute) or not isinstance(node.ctx, ast.Load):
            continue
        parts = _dotted(node)
        if parts and parts[0] in bound:
            use(node, ".".join([bound[parts[0]], *parts[1:]]))
    return uses


def check_scripts(root: Path, names: list[str]) -> dict:
    """``policy.py`` defines ``Policy``; ``train.py``, when present, compiles."""
    source = read_script(root, POLICY)
    if source is None:
        nested = [n for n in names if n.endswith(f"/{POLICY}")]
        hint = f"; found {nested[0]}: zip the folder's contents, not the folder" if nested else ""
        raise Rejected(POLICY, "policy-missing", f"the zip has no {POLICY} at its root{hint}")
    defined = top_level_names(parse_script(POLICY, source, "policy"))
    del source
    if "Policy" not in defined:
        raise Rejected(POLICY, "policy-class", "defines no top-level class Policy")
    train = read_script(root, TRAIN_SCRIPT)
    if train is not None:
        parse_script(TRAIN_SCRIPT, train, "train")
    # For the porting notes (submissions/intake/porting.py): the host never parses policy.py.
    return {"trains": train is not None, "policy_defines": sorted(set(defined))[:1000]}


def read_config(root: Path, name: str, max_bytes: int = MAX_CONFIG_BYTES, cut: bool = False):
    """A root-level text file of the submission, or None when it is absent. Longer than
    ``max_bytes``: cut there with ``cut``, else refused."""
    path = root / name
    if path.is_symlink() or not path.is_file():
        return None
    with path.open("rb") as handle:
        data = handle.read(max_bytes + 1)
    if len(data) > max_bytes:
        if not cut:
            raise Rejected(name, "file-too-large", f"is larger than {max_bytes // 1024} KiB")
        data = data[:max_bytes]
    try:
        return data.decode("utf-8-sig", errors="replace" if cut else "strict")
    except UnicodeDecodeError as error:
        raise Rejected(name, "not-utf8", f"is not UTF-8 text ({error})") from error


# YAML 1.1's plain scalars as PyYAML's safe loader resolves them (the rest stay strings).
_YAML_NULL = re.compile(r"~|null|Null|NULL")
_YAML_BOOL = {
    **dict.fromkeys(["yes", "Yes", "YES", "true", "True", "TRUE", "on", "On", "ON"], True),
    **dict.fromkeys(["no", "No", "NO", "false", "False", "FALSE", "off", "Off", "OFF"], False),
}
_YAML_INT = re.compile(r"[-+]?(0|[1-9][0-9_]*)")
_YAML_BASED_INT = re.compile(r"([-+]?)0(b[01_]+|x[0-9a-fA-F_]+|[0-7_]+)")
_YAML_FLOAT = re.compile(r"[-+]?([0-9][0-9_]*)?\.[0-9_]*([eE][-+][0-9]+)?")
_YAML_SPECIAL_FLOAT = {
    **dict.fromkeys((f"{s}.{w}" for s in ("", "+") for w in ("inf", "Inf", "INF")), "inf"),
    **dict.fromkeys((f"-.{w}" for w in ("inf", "Inf", "INF")), "-inf"),
    **dict.fromkeys((".nan", ".NaN", ".NAN"), "nan"),
}
_OPTION_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
# A plain value starting with one of these is YAML structure (a list, a mapping, an anchor, an
# alias, a tag, block text, a directive), which no option of agent.yaml takes.
_STRUCTURE = tuple("[]{}&*!|>%@`")
_DOUBLE_QUOTED_ESCAPES = {"\\": "\\", '"': '"', "/": "/", "n": "\n", "t": "\t", "0": "\0"}


def _yaml_error(number: int, message: str) -> Rejected:
    where = f"line {number}: " if number else ""
    return Rejected(AGENT_YAML, "agent-yaml", f"{where}{message}")


def _plain_scalar(text: str):
    if not text or _YAML_NULL.fullmatch(text):
        return None
    if text in _YAML_BOOL:
        return _YAML_BOOL[text]
    if _YAML_INT.fullmatch(text):
        return int(text.replace("_", ""))
    if based := _YAML_BASED_INT.fullmatch(text):
        sign, digits = based.groups()
        base = {"b": 2, "x": 16}.get(digits[0], 8)
        number = int(digits.replace("_", "").lstrip("bx") or "0", base)
        return -number if sign == "-" else number
    if text in _YAML_SPECIAL_FLOAT:
        return float(_YAML_SPECIAL_FLOAT[text])
    if _YAML_FLOAT.fullmatch(text) and any(c.isdigit() for c in text):
        return float(text.replace("_", ""))
    return text


def _quoted_scalar(text: str, number: int) -> tuple[str, str]:
    """The quoted string at the start of ``text`` and what follows it on the line."""
    quote, value, at = text[0], [], 1
    while at < len(text):
        char = text[at]
        if char == quote:
            if quote == "'" and text[at + 1 : at + 2] == "'":
                value.append("'")
                at += 2
                continue
            return "".join(value), text[at + 1 :]
        if char == "\\" and quote == '"':
            escaped = _DOUBLE_QUOTED_ESCAPES.get(text[at + 1 : at + 2])
            if escaped is None:
                raise _yaml_error(number, 'only \\\\, \\", \\/, \\n, \\t and \\0 escape in quotes')
            value.append(escaped)
            at += 2
            continue
        value.append(char)
        at += 1
    raise _yaml_error(number, "a quoted value is not closed on its line")


def _value(text: str, number: int):
    """The scalar of an ``option: value`` line after the colon (comment included)."""
    text = text.strip(" \t")
    if text[:1] in ("'", '"'):
        value, rest = _quoted_scalar(text, number)
        rest = rest.strip(" \t")
        if rest and not rest.startswith("#"):
            raise _yaml_error(number, "text after a quoted value")
        return value
    if text.startswith("#"):
        return None
    plain = re.split(r"[ \t]#", text, maxsplit=1)[0].rstrip(" \t")
    if plain.startswith(_STRUCTURE) or plain in ("-", "?") or plain.startswith(("- ", "? ")):
        raise _yaml_error(
            number,
            "an option's value is one plain value (no lists, mappings, anchors, aliases, tags "
            "or block text)",
        )
    if ": " in plain or plain.endswith(":"):
        raise _yaml_error(number, "one `option: value` per line (options are not nested)")
    return _plain_scalar(plain)


def parse_agent_yaml(text: str) -> dict:
    """``agent.yaml``'s options: a flat mapping of ``option: value`` lines (comments allowed), the
    YAML subset every option needs. Read line by line: nothing in it can nest, so no document
    can make this (or the host, which receives only the flat result) recurse or grow."""
    options: dict = {}
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.rstrip(" \t\r")
        if not line or line.lstrip(" \t").startswith("#"):
            continue
        if line in ("---", "...") and not options:
            continue
        if line[0] in " \t":
            raise _yaml_error(number, "indented: options are not nested (one `option: value`)")
        if line.startswith(("- ", "-\t")) or line == "-":
            raise _yaml_error(0, "must be a mapping of option: value")
        name, colon, rest = line.partition(":")
        if not colon or (rest and rest[0] not in " \t"):
            raise _yaml_error(number, "not an `option: value` line")
        if not _OPTION_NAME.fullmatch(name) or len(name) > MAX_OPTION_NAME:
            raise _yaml_error(number, f"{name[:MAX_OPTION_NAME]!r} is not an option's name")
        if name in options:
            raise _yaml_error(number, f"{name} is set twice")
        value = _value(rest, number)
        if isinstance(value, str) and len(value) > MAX_OPTION_VALUE:
            raise _yaml_error(number, f"{name}'s value is over {MAX_OPTION_VALUE} characters")
        options[name] = value
        if len(options) > MAX_OPTIONS:
            raise _yaml_error(number, f"more than {MAX_OPTIONS} options")
    return options


def check_requirements(text: str) -> None:
    """Every line of ``requirements.txt`` short and shallow enough for the host's parser."""
    for number, line in enumerate(text.splitlines(), start=1):
        entry = f"{REQUIREMENTS}:{number}"
        if len(line) > MAX_REQUIREMENT_CHARS:
            raise Rejected(
                entry, "requirements-syntax", f"a line is over {MAX_REQUIREMENT_CHARS} characters"
            )
        depth = deepest = 0
        for char in line:
            depth += (char == "(") - (char == ")")
            deepest = max(deepest, depth)
        if deepest > MAX_REQUIREMENT_NESTING:
            raise Rejected(
                entry,
                "requirements-syntax",
                f"parentheses nest {deepest} deep (at most {MAX_REQUIREMENT_NESTING})",
            )


def read_contents(root: Path) -> dict:
    """What the files configuring the submission say, as the verdict's flat, bounded fields:
    ``agent_options`` (agent.yaml), ``requirements`` and ``explanation`` (texts)."""
    agent_yaml = read_config(root, AGENT_YAML)
    explanation = read_config(root, EXPLANATION, MAX_EXPLANATION_CHARS * 4, cut=True)
    requirements = read_config(root, REQUIREMENTS)
    check_requirements(requirements or "")
    return {
        "agent_options": parse_agent_yaml(agent_yaml) if agent_yaml is not None else {},
        "requirements": requirements,
        "explanation": None if explanation is None else explanation[:MAX_EXPLANATION_CHARS],
    }


def porting_facts(root: Path) -> dict:
    """What the porting notes need of the configuration files, read leniently: a file the
    checks refuse is named by them, and still gets its notes."""
    try:
        options = parse_agent_yaml(read_config(root, AGENT_YAML) or "")
    except Rejected:
        options = {}
    try:
        requirements = read_config(root, REQUIREMENTS) or ""
        check_requirements(requirements)
    except Rejected:
        requirements = ""
    form = options.get("observation_format")
    return {
        "observation_format": form if isinstance(form, str) else None,
        "requirements": requirements,
        "smarts_config": (root / SMARTS_CONFIG).is_file(),
    }


def check_submission(upload: Path, dest: Path, limits: Limits) -> dict:
    """Check the zip, extract it into ``dest`` and check what it holds; the report's fields."""
    budget = submission_budget(limits)
    with open_zip(upload, limits) as archive:
        check_directory(archive, limits, budget)
        names = archive.namelist()
        written = extract(archive, dest)
    # The outer entries were counted already: only what nested archives hold is added.
    scratch = dest.parent / "nested-scratch"
    try:
        for path in written:
            shown = path.relative_to(dest).as_posix()
            check_nested_file(path, shown, limits, budget, 0, scratch)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    (dest.parent / PORTING).write_text(json.dumps(scan_sources(dest) | porting_facts(dest)))
    return check_scripts(dest, names) | read_contents(dest)


def unpack_wheels(wheels: Path, dest: Path, limits: Limits) -> dict:
    """Install each wheel of ``wheels`` into ``dest/<wheel name>`` as ``pip install --target``
    would (a wheel is a zip; installing one runs no code), under the archive rules, one wheel's
    cap on its file, and the stack's caps on the unpacked bytes and files of all of them. A
    wheel's ratio is also judged whole: entries each under the ratio's floor add up."""
    budget = Budget(limits.max_deps_files, limits.max_deps_bytes, "requirements, all wheels")
    dest.mkdir(parents=True, exist_ok=True)
    installed = []
    for wheel in sorted(wheels.glob("*.whl")):
        shown = f"requirements.txt: {wheel.name}"
        with open_zip(wheel, limits, shown, size_rule="max-wheel-bytes") as archive:
            check_directory(
                archive,
                limits,
                budget,
                prefix=f"{wheel.name}!",
                ratio_floor=WHEEL_ENTRY_RATIO_FLOOR_BYTES,
            )
            check_whole_ratio(archive, wheel, limits, shown)
            staging = dest.parent / "wheel-staging"
            shutil.rmtree(staging, ignore_errors=True)
            extract(archive, staging, prefix=f"{wheel.name}!")
        target = dest / wheel.name
        target.mkdir()
        merge_wheel(staging, target)
        shutil.rmtree(staging, ignore_errors=True)
        installed.append(wheel.name)
    return {"wheels": installed}


def check_whole_ratio(archive: zipfile.ZipFile, path: Path, limits: Limits, shown: str) -> None:
    unpacked = sum(info.file_size for info in archive.infolist())
    ratio = unpacked / max(path.stat().st_size, 1)
    if unpacked > RATIO_FLOOR_BYTES and ratio > limits.max_compression_ratio:
        raise Rejected(
            shown,
            "compression-ratio",
            f"unpacks {ratio:.0f}:1 as a whole (limit {limits.max_compression_ratio:g}:1): "
            "a zip bomb?",
        )


def merge_wheel(staging: Path, dest: Path) -> None:
    """Move a wheel's files into ``dest``: its ``.data/purelib`` and ``platlib`` to the top, the
    rest of ``.data`` (scripts, headers, data files) left out, as ``--target`` installs do."""
    for data in staging.glob("*.data"):
        for kind in ("purelib", "platlib"):
            if (data / kind).is_dir():
                _merge(data / kind, dest)
        shutil.rmtree(data)
    _merge(staging, dest)


def _merge(source: Path, dest: Path) -> None:
    for item in source.iterdir():
        target = dest / item.name
        if item.is_dir() and target.is_dir():
            _merge(item, target)
        elif not target.exists():
            item.rename(target)


def main(argv: list[str]) -> int:
    """``MODE INPUT OUTPUT``: ``submission`` (INPUT/upload.zip into OUTPUT/submission) or
    ``wheels`` (INPUT/wheels/*.whl, each into OUTPUT/deps/<wheel>); limits from
    INPUT/limits.json."""
    mode, source, output = argv[0], Path(argv[1]), Path(argv[2])
    limits = Limits(**json.loads((source / LIMITS).read_text()))
    try:
        if mode == "submission":
            report = check_submission(source / UPLOAD, output / SUBMISSION_DIR, limits)
        elif mode == "wheels":
            report = unpack_wheels(source / WHEELS_DIR, output / DEPS_DIR, limits)
        else:
            raise SystemExit(f"unknown mode {mode!r}")
        verdict = {"ok": True, **report}
    except Rejected as error:
        verdict = {"ok": False, "entry": error.entry, "rule": error.rule, "message": error.message}
    except MemoryError:
        verdict = {
            "ok": False,
            "entry": ARCHIVE,
            "rule": "intake-memory",
            "message": "checking the zip needed more memory than its limit",
        }
    (output / REPORT).write_text(json.dumps(verdict))
    return 0


if __name__ == "__main__":
    sys.setrecursionlimit(max(sys.getrecursionlimit(), 1000))
    os.umask(0o022)
    raise SystemExit(main(sys.argv[1:]))
