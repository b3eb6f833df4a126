"""Surface ID: flat surfaces worth asking about, from what the drone sees."""

from companion.perception.surface_id import Candidate, SiteCheck, check_site, quadrant_fallback, surface_id

__all__ = ["Candidate", "SiteCheck", "check_site", "quadrant_fallback", "surface_id"]
