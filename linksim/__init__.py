"""linksim: the world around the link -- impaired channels, simulated modems and arm, benchmarks."""

__all__: list[str] = []
