# Coarse proximity query between two convex-hull hierarchies (DESIGN.md §3): best-first traversal,
# GJK distance, libccd MPR for penetrating leaf pairs.
target_sources(haptic_core PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/src/hull_proximity.cc)
