# Haptic texture bake (Embree ray casting), DESIGN.md §2.
target_sources(haptic_model_build PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/src/model_build/texture_bake.cc)
