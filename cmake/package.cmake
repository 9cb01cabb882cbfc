# The CMake package for C++ users: `cmake --install` puts the module libraries, their
# headers (under include/sonotrace, with the same paths as in the source tree) and
# sonotraceConfig.cmake under the prefix. A user's project then writes
#   find_package(sonotrace CONFIG REQUIRED)   # CMAKE_PREFIX_PATH=<prefix>
#   target_link_libraries(app PRIVATE sonotrace::imaging)   # or ::scene, ::dataset, ::cli
# The targets are the modules, each bringing those it builds on (tissue <- probe <-
# simulator <- imaging, phantoms <- scene <- dataset, validation <- cli).
include(GNUInstallDirs)
include(CMakePackageConfigHelpers)

set(sonotrace_exported_modules
  options:sonotrace_options base:sonotrace_base tissue:sonotrace_tissue probe:sonotrace_probe
  simulator:sonotrace_simulator imaging:sonotrace_imaging phantoms:sonotrace_phantoms
  validation:sonotrace_validation scene:sonotrace_scene dataset:sonotrace_dataset
  dataset_mpi:sonotrace_dataset_mpi cli:sonotrace_ui)
# The command line's GPU renderer, where the build has it (OpenGL and EGL).
set(SONOTRACE_PACKAGE_GL OFF)
if(TARGET sonotrace_gl_pbvr)
  list(APPEND sonotrace_exported_modules gl_pbvr:sonotrace_gl_pbvr)
  set(SONOTRACE_PACKAGE_GL ON)
endif()
set(sonotrace_exported_targets "")
foreach(entry IN LISTS sonotrace_exported_modules)
  string(REPLACE ":" ";" pair "${entry}")
  list(GET pair 0 export_name)
  list(GET pair 1 target)
  set_target_properties(${target} PROPERTIES EXPORT_NAME ${export_name})
  list(APPEND sonotrace_exported_targets ${target})
endforeach()

install(TARGETS ${sonotrace_exported_targets} EXPORT sonotraceTargets
        ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR})
foreach(module tissue probe simulator imaging phantoms ui/dataset ui/cli)
  install(DIRECTORY ${PROJECT_SOURCE_DIR}/${module}/ DESTINATION include/sonotrace/${module}
          FILES_MATCHING PATTERN "*.h" PATTERN "presets" EXCLUDE)
endforeach()
install(FILES ${PROJECT_BINARY_DIR}/generated/sonotrace_version.h
              ${PROJECT_BINARY_DIR}/generated/tissue_presets.h
        DESTINATION include/sonotrace)

set(sonotrace_cmake_dir ${CMAKE_INSTALL_LIBDIR}/cmake/sonotrace)
install(EXPORT sonotraceTargets NAMESPACE sonotrace:: DESTINATION ${sonotrace_cmake_dir})
configure_package_config_file(${PROJECT_SOURCE_DIR}/cmake/sonotraceConfig.cmake.in
  ${PROJECT_BINARY_DIR}/sonotraceConfig.cmake INSTALL_DESTINATION ${sonotrace_cmake_dir}
  PATH_VARS CMAKE_INSTALL_DATADIR)
write_basic_package_version_file(${PROJECT_BINARY_DIR}/sonotraceConfigVersion.cmake
  VERSION ${PROJECT_VERSION} COMPATIBILITY SameMinorVersion)
install(FILES ${PROJECT_BINARY_DIR}/sonotraceConfig.cmake
              ${PROJECT_BINARY_DIR}/sonotraceConfigVersion.cmake
              ${PROJECT_SOURCE_DIR}/cmake/FindNiftiIO.cmake
              ${PROJECT_SOURCE_DIR}/cmake/FindOpenCVParts.cmake
        DESTINATION ${sonotrace_cmake_dir})
