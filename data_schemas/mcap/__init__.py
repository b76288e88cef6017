"""The log format's file I/O: writing, reading, indexing, checking and recovering MCAP logs.

One module a job; import them explicitly (``from data_schemas.mcap.read import LogReader``), so
that importing this package stays cheap.
"""
