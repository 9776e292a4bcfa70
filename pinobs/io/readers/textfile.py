"""What a text log file is before it is parsed: its encoding, a compressed or binary file
named with what to do, whether rows follow the header."""

from __future__ import annotations

import zipfile
from pathlib import Path

#: Magic bytes of compressed files, their kind and a command that decompresses them.
_COMPRESSED = (
    (b"\x1f\x8b", "gzip", "gunzip -k"),
    (b"BZh", "bzip2", "bunzip2 -k"),
    (b"\xfd7zXZ\x00", "xz", "unxz -k"),
    (b"\x28\xb5\x2f\xfd", "zstd", "unzstd"),
)


def _zip_hint(path: Path) -> str:
    """What a zip archive read as text is: an .npz misnamed, or a zipped log to unzip."""
    try:
        with zipfile.ZipFile(path) as z:
            names = z.namelist()
    except (zipfile.BadZipFile, OSError):
        names = []
    if names and all(n.endswith(".npy") for n in names):
        return " (it is an .npz archive of arrays: name it .npz)"
    return f" (it is a zip archive of {names}: unzip it first, e.g. `unzip {path}`)"


def undecodable_line(path: Path) -> tuple[int, str]:
    """The first line of ``path`` that is not UTF-8, and a hint about what the file is."""
    with path.open("rb") as fh:
        head = fh.read(8)
    hint = ""
    if head.startswith((b"\xff\xfe", b"\xfe\xff")):
        hint = " (it starts with a UTF-16 byte-order mark: re-save it as UTF-8)"
    elif head.startswith(b"PK"):
        hint = _zip_hint(path)
    elif head.startswith((b"ARROW1", b"FEA1")):  # (a sweep found it "not UTF-8", no more)
        hint = (
            " (it is a Feather / Arrow IPC file, which pinobs does not read: convert it to "
            "Parquet, e.g. pandas.read_feather(path).to_parquet('log.parquet'))"
        )
    elif head.startswith(b"\x93NUMPY"):
        hint = " (it is a .npy array: save the log with np.savez(path, t=..., q=..., tau=...))"
    else:  # compressed text: a sweep found a .csv.gz refused with no word of why
        for magic, kind, tool in _COMPRESSED:
            if head.startswith(magic):
                hint = f" (it is {kind}-compressed: decompress it first, e.g. `{tool} {path}`)"
    with path.open("rb") as fh:
        for number, raw in enumerate(fh, start=1):
            if number == 1 and raw.startswith(b"\xef\xbb\xbf"):
                raw = raw[3:]
            try:
                raw.decode("utf-8")
            except UnicodeDecodeError:
                return number, hint
    return 0, hint


def has_data_after_header(path: Path) -> bool:
    """Whether anything but white space follows line 1, whatever the line ends (``\n``,
    ``\r\n`` or a lone ``\r``: a sweep found every row of a CR-only file lost)."""
    header = True
    with path.open("rb") as fh:
        for block in iter(lambda: fh.read(1 << 16), b""):
            if header:
                ends = [i for i in (block.find(b"\n"), block.find(b"\r")) if i >= 0]
                if not ends:
                    continue
                block, header = block[min(ends) + 1 :], False
            if block.strip():
                return True
    return False


def has_binary_head(path: Path) -> bool:
    with path.open("rb") as fh:
        head = fh.read(4096)
    if head.startswith(b"\xef\xbb\xbf"):
        head = head[3:]
    try:
        head.decode("utf-8")
    except UnicodeDecodeError as exc:
        return exc.start < len(head) - 4  # not just a character cut by the 4096-byte window
    return b"\x00" in head
