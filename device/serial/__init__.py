"""The serial backend, the wire protocol (docs/wire-protocol.md) and the device emulator."""

__all__: list[str] = []
