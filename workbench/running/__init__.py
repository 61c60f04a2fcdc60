"""Running: one run put together (scene -> model -> discretisation -> scheme -> Dataset), its restart, the checks
before it, the thread pools.
"""
