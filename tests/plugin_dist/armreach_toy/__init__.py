"""A throwaway task plugin: reach with a 20 cm tolerance. Installed only by the tests."""
