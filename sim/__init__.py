"""The Driving Arena simulator: SUMO background traffic, our own ego vehicles, observations,
geometry events and the per-step episode record."""
