"""A copy-me armreach task plugin (see tasks/template/README.md)."""
