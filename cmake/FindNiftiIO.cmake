# Finds Debian's niftilib (libniftiio-dev, libznz-dev). Debian 12's own NIFTIConfig.cmake
# (libnifti2-dev) references /usr/lib/libznz.so.3.0.0, which the package installs under
# the multiarch directory instead, so find_package(NIFTI CONFIG) fails; this module does not.
# Defines the imported target NIFTI::niftiio.
find_path(NiftiIO_INCLUDE_DIR nifti1_io.h PATH_SUFFIXES nifti)
find_library(NiftiIO_LIBRARY niftiio)
find_library(NiftiIO_ZNZ_LIBRARY NAMES znz libznz.so.3)
include(FindPackageHandleStandardArgs)
find_package_handle_standard_args(NiftiIO REQUIRED_VARS NiftiIO_INCLUDE_DIR NiftiIO_LIBRARY NiftiIO_ZNZ_LIBRARY)
if(NiftiIO_FOUND AND NOT TARGET NIFTI::niftiio)
  add_library(NIFTI::niftiio INTERFACE IMPORTED)
  set_target_properties(NIFTI::niftiio PROPERTIES INTERFACE_INCLUDE_DIRECTORIES "${NiftiIO_INCLUDE_DIR}")
  target_link_libraries(NIFTI::niftiio INTERFACE "${NiftiIO_LIBRARY}" "${NiftiIO_ZNZ_LIBRARY}" ZLIB::ZLIB m)
endif()
