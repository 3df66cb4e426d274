"""Robot descriptions shipped with armreach-grasp (found with ``importlib.resources``)."""
