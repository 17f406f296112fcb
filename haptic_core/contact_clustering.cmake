# Contact clustering (DESIGN.md §3): hull-pair contacts grouped into at most kMaxContacts texture
# windows, after Kim, Otaduy, Lin & Manocha (2002/2003).
target_sources(haptic_core PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/src/contact_clustering.cc)
