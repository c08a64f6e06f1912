"""The lab harness above the app: protocols and the benchmark of the methods, real data against
its references, confidence checks, fuzzing, speed, load, batch and live benchmarks."""
