"""Robot descriptions bundled with armreach (installed as ``armreach_core.assets``)."""
