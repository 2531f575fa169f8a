"""The built-in demo: scenes synthesised by Servant's own code, so `servant demo` runs anywhere."""
