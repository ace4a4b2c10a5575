"""Benchmarks: figures for the issues' bars (``make bench``). Not tests: nothing here asserts times."""
