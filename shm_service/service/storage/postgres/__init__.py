"""The PostgreSQL engine under the repositories (``[storage] url = "postgresql://..."``): its
connection, which runs the repositories' statements (``_connection``), its transactions and
retries (``_db``), the versioned schema migrated under an advisory lock (``_schema``) and the
leases of a fleet's nodes with their fencing tokens (``_leases``). May import ``contract`` only.
"""

from .._url import is_postgres_url, redact
from ._db import PgDatabase
from ._leases import Lease, Leases, StaleLease, check_fence

__all__ = ["Lease", "Leases", "PgDatabase", "StaleLease", "check_fence", "is_postgres_url", "redact"]
