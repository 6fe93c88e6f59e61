"""Import the project under atheris instrumentation when a harness runs as a fuzzer."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator


@contextlib.contextmanager
def instrumented(active: bool) -> Iterator[None]:
    """``atheris.instrument_imports()`` for the project's packages when ``active``.

    Harnesses pass ``__name__ == "__main__"``: under libFuzzer the project's
    modules are instrumented for coverage; imported by pytest to replay the
    corpus, nothing is instrumented and atheris need not be installed.
    """
    if not active:
        yield
        return
    import atheris

    with atheris.instrument_imports(include=["serialsocket", "tcpstream"]):
        yield
