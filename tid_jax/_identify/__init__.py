"""The inerter device and its identification from test records."""
