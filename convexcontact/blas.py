"""BLAS's thread pools, limited where the library's own work does not gain from them (threadpoolctl)."""

from __future__ import annotations

import functools

import threadpoolctl


@functools.cache
def pools() -> threadpoolctl.ThreadpoolController:
    """The process's thread pools (scanned once: threadpoolctl reads the loaded libraries)."""
    return threadpoolctl.ThreadpoolController()


def limited(threads: int):
    """A context with every BLAS pool on at most ``threads`` threads, the pools' own settings given back after it."""
    return pools().limit(limits=threads, user_api="blas")
