"""What the job commands share: --url/--token options, an SDK client, SDK errors as one line."""

from __future__ import annotations

import contextlib
from typing import TYPE_CHECKING, Annotated, Iterator, Optional

import typer

from .errors import fail

if TYPE_CHECKING:
    from client_sdk import Client

__all__ = ["TokenOpt", "UrlOpt", "sdk_client"]

UrlOpt = Annotated[Optional[str], typer.Option(
    "--url", envvar="TWB_URL", show_default=False,
    help="Testbed URL (default: http://127.0.0.1:8000).")]
TokenOpt = Annotated[Optional[str], typer.Option(
    "--token", envvar="TWB_TOKEN", show_default=False,
    help="Access token (default: the token file twb up writes, TWB_DATA_DIR/token or ./twb-data/token).")]


@contextlib.contextmanager
def sdk_client(url: Optional[str], token: Optional[str], timeout: float = 30.0) -> Iterator["Client"]:
    """An SDK :class:`Client`; its errors leave as one clear line (``CliError``)."""
    from client_sdk import Client, NotFound, TransportError, TwbError, Unauthorized, WaitTimeout, token_file

    client = Client(url, token, timeout=timeout)
    try:
        yield client
    except Unauthorized as exc:
        hint = ("give --token, set TWB_TOKEN, or run where `twb up` wrote "
                f"{token_file()}" if client.token is None else "check --token / TWB_TOKEN")
        fail(f"the testbed at {client.url} refused the request: {exc.detail} ({hint})")
    except NotFound as exc:
        fail(f"{exc.detail}" + (f" ({exc.method} {exc.url})" if exc.url else ""))
    except TransportError as exc:
        fail(f"{exc} (is the testbed running? start it with `twb up`, or give --url / TWB_URL)")
    except WaitTimeout as exc:
        fail(str(exc), code=3)
    except TwbError as exc:
        fail(str(exc))
    finally:
        client.close()
