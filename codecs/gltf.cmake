# glTF 2.0 scene loading (gltf_scene.cc). tiny_gltf.h is compiled into this one unit under the
# name proj_tinygltf, so that it cannot clash with the tinygltf copy libdraco.so exports
# (../shared/design/DEPENDENCIES.md trap 1). Never link TinyGLTF::TinyGLTF.
target_sources(codecs PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/src/gltf_scene.cc)
target_compile_definitions(codecs PRIVATE tinygltf=proj_tinygltf)
# The public header names nlohmann::json (SceneSummaryJson), hence PUBLIC.
target_link_libraries(codecs PUBLIC nlohmann_json::nlohmann_json)
