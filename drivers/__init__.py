"""Bench device drivers: bytes and CAN frames in, typed readings with time stamps and status out.

Transport-agnostic (pyserial URLs, python-can buses); does not import benchlab or sim_bench.
"""
