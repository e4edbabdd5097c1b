"""The release of the stack (CHANGELOG.md; every package.xml and setup.py say the same, tests/test_versions.py)."""

__version__ = "0.17.0"
