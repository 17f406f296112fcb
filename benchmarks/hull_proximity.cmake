# Coarse proximity query between convex-hull hierarchies on the seed scenes, side by side with FCL.
if(NOT TARGET fcl)
  find_package(fcl 0.7 CONFIG REQUIRED)
endif()
add_executable(hull_proximity_benchmark hull_proximity_benchmark.cc)
target_link_libraries(hull_proximity_benchmark PRIVATE benchmark::benchmark haptic_model_build fcl)
