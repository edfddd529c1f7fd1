"""Streaming multipart reception: the zip goes to disk chunk by chunk, never whole into memory,
and the upload is refused as soon as it exceeds the size cap (before reading anything when the
declared Content-Length already does)."""

from __future__ import annotations

import hashlib
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO

from python_multipart.exceptions import MultipartParseError
from python_multipart.multipart import MultipartParser, parse_options_header
from starlette.requests import Request

from server.services.errors import InvalidUpload, UploadTooLarge

FILE_FIELD = "file"
MAX_FIELD_BYTES = 64 * 1024
# Room for the other form fields and the multipart framing around the zip.
FORM_OVERHEAD_BYTES = 256 * 1024
# Caps on the form as a whole, not only per field: 8,000 fields of 64 KiB each once pushed the
# API from 115 to 588 MiB. The form has a handful of fields; headers of a part are small.
MAX_FIELDS = 16
MAX_FIELDS_TOTAL_BYTES = FORM_OVERHEAD_BYTES
MAX_PART_HEADER_BYTES = 8 * 1024


@dataclass
class ReceivedForm:
    fields: dict[str, str] = field(default_factory=dict)
    file_path: Path | None = None
    file_size: int = 0  # [bytes]
    # Of the zip, computed while it streams in (the API never reads it back for this).
    sha256: str = ""


class _Receiver:
    def __init__(self, dest_dir: Path, max_file_bytes: int) -> None:
        self.dest_dir = dest_dir
        self.max_file_bytes = max_file_bytes
        self.form = ReceivedForm()
        self._headers: dict[bytes, bytes] = {}
        self._header_field = b""
        self._header_value = b""
        self._name = ""
        self._value = bytearray()
        self._file: BinaryIO | None = None
        self._fields_bytes = 0
        self._parts = 0
        self._header_bytes = 0
        self._digest = hashlib.sha256()

    def callbacks(self) -> dict:
        return {
            "on_part_begin": self._part_begin,
            "on_header_field": self._header_field_data,
            "on_header_value": self._header_value_data,
            "on_header_end": self._header_end,
            "on_headers_finished": self._headers_finished,
            "on_part_data": self._part_data,
            "on_part_end": self._part_end,
        }

    def _part_begin(self) -> None:
        self._headers = {}
        self._value = bytearray()
        self._header_bytes = 0
        self._parts += 1
        if self._parts > MAX_FIELDS + 1:
            raise UploadTooLarge(f"the form has more than {MAX_FIELDS} fields besides the file")

    def _count_header(self, size: int) -> None:
        self._header_bytes += size
        if self._header_bytes > MAX_PART_HEADER_BYTES:
            raise UploadTooLarge(f"a form part's headers exceed {MAX_PART_HEADER_BYTES} bytes")

    def _header_field_data(self, data: bytes, start: int, end: int) -> None:
        self._count_header(end - start)
        self._header_field += data[start:end]

    def _header_value_data(self, data: bytes, start: int, end: int) -> None:
        self._count_header(end - start)
        self._header_value += data[start:end]

    def _header_end(self) -> None:
        self._headers[self._header_field.lower()] = self._header_value
        self._header_field = self._header_value = b""

    def _headers_finished(self) -> None:
        _, options = parse_options_header(self._headers.get(b"content-disposition", b""))
        self._name = options.get(b"name", b"").decode("utf-8", "replace")
        if self._name == FILE_FIELD:
            if self._file is not None:
                raise InvalidUpload("send exactly one file (field 'file')")
            self._file = tempfile.NamedTemporaryFile(  # noqa: SIM115  (closed in _part_end)
                dir=self.dest_dir, prefix="upload-", suffix=".zip", delete=False
            )
            self.form.file_path = Path(self._file.name)

    def _part_data(self, data: bytes, start: int, end: int) -> None:
        if self._name == FILE_FIELD and self._file is not None:
            self.form.file_size += end - start
            if self.form.file_size > self.max_file_bytes:
                raise UploadTooLarge(
                    f"the zip exceeds the limit of {self.max_file_bytes // 2**20} MiB"
                )
            self._file.write(data[start:end])
            self._digest.update(data[start:end])
        else:
            self._value += data[start:end]
            self._fields_bytes += end - start
            if len(self._value) > MAX_FIELD_BYTES:
                raise InvalidUpload(f"form field {self._name!r:.80} is longer than 64 KiB")
            if self._fields_bytes > MAX_FIELDS_TOTAL_BYTES:
                raise UploadTooLarge(
                    f"the form fields exceed {MAX_FIELDS_TOTAL_BYTES // 1024} KiB in total"
                )

    def _part_end(self) -> None:
        if self._name == FILE_FIELD and self._file is not None:
            self._file.close()
            self.form.sha256 = self._digest.hexdigest()
        else:
            self.form.fields[self._name] = self._value.decode("utf-8", "replace")

    def discard(self) -> None:
        if self._file is not None:
            self._file.close()
        if self.form.file_path is not None:
            self.form.file_path.unlink(missing_ok=True)


async def receive_form(request: Request, dest_dir: Path, max_file_bytes: int) -> ReceivedForm:
    """Read a ``multipart/form-data`` body with one zip in field ``file`` to ``dest_dir``."""
    declared = request.headers.get("content-length")
    max_request_bytes = max_file_bytes + FORM_OVERHEAD_BYTES
    if declared and declared.isdigit() and int(declared) > max_request_bytes:
        raise UploadTooLarge(
            f"the upload ({int(declared) / 2**20:.0f} MiB) exceeds the limit of "
            f"{max_file_bytes // 2**20} MiB"
        )
    content_type, options = parse_options_header(request.headers.get("content-type", ""))
    boundary = options.get(b"boundary")
    if content_type != b"multipart/form-data" or not boundary:
        raise InvalidUpload("send the submission as multipart/form-data")
    dest_dir.mkdir(parents=True, exist_ok=True)
    receiver = _Receiver(dest_dir, max_file_bytes)
    parser = MultipartParser(boundary, receiver.callbacks())
    received = 0
    try:
        async for chunk in request.stream():
            # The request as a whole, framing included: a chunked body declares no length.
            received += len(chunk)
            if received > max_request_bytes:
                raise UploadTooLarge(
                    f"the upload exceeds the limit of {max_file_bytes // 2**20} MiB "
                    f"(plus {FORM_OVERHEAD_BYTES // 1024} KiB for the form)"
                )
            parser.write(chunk)
        parser.finalize()
    except MultipartParseError as exc:
        receiver.discard()
        raise InvalidUpload(f"malformed multipart body: {exc}") from exc
    except BaseException:
        receiver.discard()
        raise
    if receiver.form.file_path is None:
        raise InvalidUpload("no zip attached: send it in the form field 'file'")
    return receiver.form
