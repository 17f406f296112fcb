add_library(haptic_model_build src/model_build/mesh_decimation.cc
                               src/model_build/haptic_model_build.cc)
target_include_directories(haptic_model_build PUBLIC ${CMAKE_CURRENT_SOURCE_DIR}/include)
target_link_libraries(haptic_model_build PUBLIC haptic_core
                      PRIVATE OpenMeshCore OpenMeshTools embree Qhull::qhull_r PkgConfig::SODIUM)
# Stages written by separate hands; each file adds its sources to haptic_model_build.
include(${CMAKE_CURRENT_SOURCE_DIR}/model_build_bake.cmake OPTIONAL)
include(${CMAKE_CURRENT_SOURCE_DIR}/model_build_hulls.cmake OPTIONAL)
