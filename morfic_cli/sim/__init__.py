"""Simulation backends: batched MuJoCo physics behind one small protocol (cpu now, gpu later)."""
