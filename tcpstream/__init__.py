"""tcpstream: fixed-size manipulator command packets over any reliable byte stream."""

__all__: list[str] = []
