"""The PostgreSQL test server (tests/ground/postgres.py) for the store tests."""

from .postgres import postgres_dsn, postgres_server

__all__ = ["postgres_dsn", "postgres_server"]
