"""Results for people: rerun recordings, static figures and reports.

See docs/architecture.md for what this package owns and may import.
"""
