"""Opening the cache a location names: a local folder (``Store``) or an object-store URL (``ObjectStore``)."""
from __future__ import annotations

from .cache_root import is_url
from .object_store import ObjectStore
from .store import Store


def open_store(location: str, warn: bool = True) -> Store:
    """The store of the cache at ``location``: an :class:`ObjectStore` for a URL (``s3://bucket/prefix``), else a
    :class:`Store` of the local folder. ``warn``: print one warning per unreadable entry found (workers pass
    False: the client warns)."""
    if is_url(location):
        return ObjectStore(location, warn=warn)
    return Store(location, warn=warn)
