"""An export as a download's body: the extra checked, the file written into a spooled temporary file (in the
calling worker thread, never on the event loop), then read back in chunks."""

from __future__ import annotations

import tempfile
from typing import Iterator, Sequence

from ..errors import NotInstalled
from .convert import write_export
from .formats import INSTALL_HINT, ExportFormat, missing_packages
from .record import RunRecord

__all__ = ["CHUNK_BYTES", "SPOOL_BYTES", "download_headers", "export_chunks", "require_format"]

#: bytes per chunk of the response; exports larger than SPOOL_BYTES wait on disk, not in memory
CHUNK_BYTES = 256 * 1024
SPOOL_BYTES = 32 * 1024 * 1024


def require_format(fmt: ExportFormat) -> None:
    """Raise :class:`~server.errors.NotInstalled` (501) naming the install command when ``fmt``'s packages
    are missing."""
    missing = missing_packages(fmt)
    if missing:
        raise NotInstalled(f"exporting {fmt.value} needs the optional packages of the `export` extra "
                           f"(missing: {', '.join(missing)}): install them on the testbed's server with "
                           f"{INSTALL_HINT}")


def export_chunks(records: Sequence[RunRecord], fmt: ExportFormat, name: str, *,
                  experiment: bool = False) -> tuple[Iterator[bytes], int]:
    """``records`` written as ``fmt`` (blocking: call it in a worker thread): an iterator over the file's bytes in
    :data:`CHUNK_BYTES` chunks (it deletes the file when done or closed) and the file's size in bytes."""
    spool = tempfile.SpooledTemporaryFile(max_size=SPOOL_BYTES, prefix="twb-export-")
    try:
        write_export(records, fmt, spool, name=name, experiment=experiment)  # type: ignore[arg-type]
        size = spool.tell()
        spool.seek(0)
    except BaseException:
        spool.close()
        raise

    def chunks() -> Iterator[bytes]:
        try:
            while chunk := spool.read(CHUNK_BYTES):
                yield chunk
        finally:
            spool.close()

    return chunks(), size


def download_headers(filename: str, size: int) -> dict[str, str]:
    """The headers of an export's download: its file name and length."""
    return {"Content-Disposition": f'attachment; filename="{filename}"', "Content-Length": str(size)}
