"""Output: the result Dataset's schema and recording, netCDF archives written atomically, ParaView files.
"""
