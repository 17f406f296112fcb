# Convex-hull hierarchy (DESIGN.md §2): the data structure and its queries live in haptic_core
# (no qhull, read near the 1 kHz loop); the builder lives in haptic_model_build (qhull, reentrant C
# API, linked privately there).
target_sources(haptic_core PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/src/hull_hierarchy.cc)
target_sources(haptic_model_build
               PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/src/model_build/hull_hierarchy_build.cc)
