"""`aeb monitor`: what the bus carries, aggregated (state), shown (view), live (main)."""
