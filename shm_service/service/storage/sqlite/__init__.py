"""The SQLite engine under the repositories: its connections, transactions and retries (``_db``),
the versioned schema and its upgrades (``_schema``) and the lock file that keeps one service per
database file (``_lock``). May import ``contract`` only.
"""
