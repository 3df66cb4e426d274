"""MuJoCo backend for armreach (registered through the ``armreach`` entry-point group)."""
