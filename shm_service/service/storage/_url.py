"""Which engine a storage target names: a ``postgresql://`` URL or a SQLite file. Needs no
database client, so settings and the command line validate a URL where PostgreSQL's client is
not installed."""

from __future__ import annotations

from urllib.parse import urlsplit, urlunsplit

__all__ = ["check_postgres_url", "is_postgres_url", "redact"]

_SCHEMES = ("postgresql", "postgres")


def is_postgres_url(target: object) -> bool:
    """Whether ``target`` (a path or a URL) names a PostgreSQL database."""
    return isinstance(target, str) and target.startswith(tuple(f"{s}://" for s in _SCHEMES))


def redact(url: str) -> str:
    """``url`` without its password (for messages, logs and the status)."""
    parts = urlsplit(url)
    if parts.password is None:
        return url
    netloc = f"{parts.username}:***@{parts.hostname or ''}" + (f":{parts.port}" if parts.port else "")
    return urlunsplit(parts._replace(netloc=netloc))


def check_postgres_url(url: str, key: str) -> str:
    """``url`` when it is a PostgreSQL URL with a host and a database
    (``postgresql://USER[:PASSWORD]@HOST[:PORT]/DB[?OPTIONS]``), else ValueError naming ``key``."""
    form = "postgresql://USER@HOST:PORT/DB"
    if not isinstance(url, str) or "://" not in url:
        raise ValueError(f"{key}={url!r} is not a URL: give {form}")
    parts = urlsplit(url)
    shown = redact(url)
    if parts.scheme not in _SCHEMES:
        raise ValueError(f"{key}={shown!r}: the scheme {parts.scheme!r} is not PostgreSQL's (give {form}; "
                         "the SQLite default needs no url: leave it out, or set db)")
    try:
        port = parts.port
    except ValueError:
        raise ValueError(f"{key}={shown!r}: the port is not a number 0-65535 ({form})") from None
    if not parts.hostname:
        raise ValueError(f"{key}={shown!r} names no host ({form})")
    if port == 0:
        raise ValueError(f"{key}={shown!r}: port 0 is not a server's ({form})")
    database = parts.path.lstrip("/")
    if not database or "/" in database:
        raise ValueError(f"{key}={shown!r} names no database (the path after the host: {form})")
    return url
