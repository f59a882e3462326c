"""`aeb monitor`: what the bus carries, aggregated (state) and shown (view)."""
