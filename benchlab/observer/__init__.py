"""Kalman observer for any thermal network: every node estimated with its spread from the sensors chosen."""
