"""Per-vertex features: SHOT, HKS and WKS descriptors and Laplace–Beltrami eigenbases."""
