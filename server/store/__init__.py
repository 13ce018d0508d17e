"""Database work of the testbed as plain functions: a session in, rows or values out.

Functions take keyword-only arguments after the session and never commit
unless their name or docstring says so; callers own the transaction.  They
are synchronous: the API calls them from its worker threads, the run
pipeline through :class:`server.pipeline.recorder.RunRecorder`.
"""
