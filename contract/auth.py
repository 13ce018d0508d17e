"""Control keys of robot ports, derived so that a testbed server and its agents agree without exchanging them.

An agent registered with a testbed server holds the server's bearer token; the
server stores only the token's hash.  Both can therefore compute, for each
robot::

    key = control_key(token_hash(token), robot_id)
        = hex HMAC-SHA256(key=token_hash.encode("ascii"),
                          msg=("twb-robot-control:" + robot_id).encode("utf-8"))

a 64-character lowercase hex string, different for every robot, which the
server sends as ``T,T,A,<key>`` to take control of the robot (see
``docs/protocol.md``, "Authentication").
"""

from __future__ import annotations

import hashlib
import hmac

__all__ = ["CONTROL_KEY_CONTEXT", "control_key", "token_hash"]

CONTROL_KEY_CONTEXT = "twb-robot-control:"
_HEX = frozenset("0123456789abcdef")


def token_hash(token: str) -> str:
    """Lowercase hex SHA-256 of the UTF-8 bearer ``token`` (what the server stores for each token)."""
    return hashlib.sha256(token.encode("utf-8")).hexdigest()


def control_key(token_hash: str, robot_id: str) -> str:
    """The control key of ``robot_id``: lowercase hex HMAC-SHA256 keyed with the ASCII bytes of
    ``token_hash`` (64 hex digits) over ``"twb-robot-control:" + robot_id`` (UTF-8).

    ``ValueError`` if ``token_hash`` is not 64 lowercase hex digits (e.g. the token itself).
    """
    if len(token_hash) != 64 or not set(token_hash) <= _HEX:
        raise ValueError("`token_hash` must be the 64 lowercase hex digits of the token's SHA-256")
    msg = (CONTROL_KEY_CONTEXT + robot_id).encode("utf-8")
    return hmac.new(token_hash.encode("ascii"), msg, hashlib.sha256).hexdigest()
