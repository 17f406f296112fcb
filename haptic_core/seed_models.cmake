# Seed benchmark models at full resolution (DESIGN.md §7): textured hammer, rough CAD part, toothed
# file and wrinkled helicoidal torus, generated procedurally at the seed's triangle counts.
target_sources(haptic_core PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/src/seed_models.cc)
