"""The ground station: a companion's MQTT feed, or a flight record, in an operator's browser.

``landfall-ground --mqtt HOST[:PORT]`` or ``landfall-ground --replay RECORD_DIR`` (docs/ground.md).
It runs on the ground, never inside the companion; it needs the ``ground`` extra (Starlette, uvicorn).
"""

from landfall_ground.messages import FeedMessage, MalformedPayload, parse
from landfall_ground.station import Station

__all__ = ["FeedMessage", "MalformedPayload", "Station", "parse"]
