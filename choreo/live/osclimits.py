"""What OSC control takes from the network at most: the one place these limits are set (the
table in docs/live.md, "Limits", says the same).

A stage network is shared and may be hostile; each limit bounds what one sender can make choreo
hold (file descriptors, memory) or do (work a packet), so that the operator's own GO still gets
through while someone else misbehaves.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class OscLimits:
    """The limits of one OSC server (tests give smaller ones)."""

    # sizes (bytes): UDP's largest datagram fits whole (nothing is cut), and a TCP message as long
    max_datagram: int = 65536
    max_message: int = 65536
    # one packet: bundles nested at most this deep, and this many elements (messages and bundles)
    max_bundle_depth: int = 8
    max_bundle_elements: int = 256
    max_arguments: int = 256  # in one packet, all its messages' together
    packet_bytes_per_token: int = 4096  # a packet spends a token of its sender's packets per 4 KB begun
    # TCP connections: open at once, from one sender's address, and the bytes queued to a peer
    # that does not read its replies (then it is closed)
    max_connections: int = 32
    max_per_sender: int = 8
    max_unsent: int = 65536
    # TCP timeouts (s): a new connection must complete a message within message_timeout_s, and
    # so must every message begun (bytes trickled without an end); one that has sent commands
    # is closed after idle_timeout_s without a message
    message_timeout_s: float = 5.0
    idle_timeout_s: float = 600.0


LIMITS = OscLimits()
