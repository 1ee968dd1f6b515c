"""pyserial URL handlers of choreo's own (`sim://`).

pyserial's `serial_for_url` imports `protocol_<scheme>` from each package named in
`serial.protocol_handler_packages`; `register()` adds this package there once.
"""

from __future__ import annotations


def register() -> None:
    import serial

    if __name__ not in serial.protocol_handler_packages:
        serial.protocol_handler_packages.append(__name__)
