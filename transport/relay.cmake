# The impairment relay (included from transport/CMakeLists.txt): the library (spec, seeded model,
# per-direction statistics, relay loop) and the ht_relay executable, which lands in
# ${CMAKE_BINARY_DIR}/transport/ht_relay like every target defined in transport/.
add_library(impairment
  ${CMAKE_CURRENT_SOURCE_DIR}/src/impairment_model.cc
  ${CMAKE_CURRENT_SOURCE_DIR}/src/impairment_relay.cc
  ${CMAKE_CURRENT_SOURCE_DIR}/src/impairment_spec.cc
)
target_include_directories(impairment PUBLIC ${CMAKE_CURRENT_SOURCE_DIR}/include)
target_link_libraries(impairment PUBLIC transport nlohmann_json::nlohmann_json)

add_executable(ht_relay ${CMAKE_CURRENT_SOURCE_DIR}/tools/ht_relay.cc)
target_link_libraries(ht_relay PRIVATE impairment CLI11::CLI11)
set_target_properties(ht_relay PROPERTIES RUNTIME_OUTPUT_DIRECTORY ${CMAKE_BINARY_DIR}/transport)
