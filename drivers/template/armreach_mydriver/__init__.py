"""A driver template for ``armreach deploy``: copy it, and put your arm's I/O in ``driver.py``."""
