# qpreduce_library(<name> EXPORT_NAME <export name> SOURCES <file>...
#                  [PUBLIC <dependency>...] [PRIVATE <dependency>...] [NO_INSTALL])
#
# A library of qpreduce (qpreduce::core, ::problems, ::testing, the deform
# plugin's targets): PIC, C++17, its public headers in include/ beside the
# calling CMakeLists.txt, aliased and exported as qpreduce::<export name>,
# linked PRIVATE to qpreduce_build_flags (warnings, sanitizers) at build time
# only. Installs the library in the qpreduceTargets export set and the
# headers under include/, unless NO_INSTALL (the caller installs it).
function(qpreduce_library name)
  cmake_parse_arguments(L "NO_INSTALL" "EXPORT_NAME" "SOURCES;PUBLIC;PRIVATE" ${ARGN})
  add_library(${name} ${L_SOURCES})
  add_library(qpreduce::${L_EXPORT_NAME} ALIAS ${name})
  set_target_properties(${name} PROPERTIES EXPORT_NAME ${L_EXPORT_NAME} OUTPUT_NAME ${name}
                                           POSITION_INDEPENDENT_CODE ON)
  target_compile_features(${name} PUBLIC cxx_std_17)
  target_include_directories(${name} PUBLIC
    $<BUILD_INTERFACE:${CMAKE_CURRENT_SOURCE_DIR}/include>
    $<INSTALL_INTERFACE:${CMAKE_INSTALL_INCLUDEDIR}>)
  target_link_libraries(${name}
    PUBLIC ${L_PUBLIC}
    PRIVATE ${L_PRIVATE} $<BUILD_INTERFACE:qpreduce_build_flags>)

  if(NOT L_NO_INSTALL)
    install(TARGETS ${name} EXPORT qpreduceTargets
            ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
            LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR})
    install(DIRECTORY include/ DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
  endif()
endfunction()
