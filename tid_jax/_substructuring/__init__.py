"""The virtual real-time substructuring test of the inerter."""
