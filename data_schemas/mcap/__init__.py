"""The log format's file I/O: writing, reading, indexing, checking and recovering MCAP logs.

One module a job; import them explicitly
(``from data_schemas.mcap.processable import ProcessableLog``), so that importing this package
stays cheap.
"""
