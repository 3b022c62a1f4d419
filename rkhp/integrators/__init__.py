"""RKHP integrators: Taylor-tower step, Newton, compiled loops, classical peers (paper §5.2)."""
