# Finds the OpenCV modules sonotrace uses (core, imgproc, videoio) from Debian's
# per-module packages (libopencv-core-dev, ...). Debian's full libopencv-dev pulls
# ~70 further packages (VTK, MPI, Qt) that we never link, so CI installs only these.
# Defines the imported target OpenCV::parts.
find_path(OpenCVParts_INCLUDE_DIR opencv2/core.hpp PATH_SUFFIXES opencv4)
set(_ocv_libs)
foreach(_m core imgproc videoio)
  find_library(OpenCVParts_${_m}_LIBRARY opencv_${_m})
  list(APPEND _ocv_libs OpenCVParts_${_m}_LIBRARY)
endforeach()
include(FindPackageHandleStandardArgs)
find_package_handle_standard_args(OpenCVParts REQUIRED_VARS OpenCVParts_INCLUDE_DIR ${_ocv_libs})
if(OpenCVParts_FOUND AND NOT TARGET OpenCV::parts)
  add_library(OpenCV::parts INTERFACE IMPORTED)
  set_target_properties(OpenCV::parts PROPERTIES INTERFACE_INCLUDE_DIRECTORIES "${OpenCVParts_INCLUDE_DIR}")
  foreach(_m core imgproc videoio)
    target_link_libraries(OpenCV::parts INTERFACE "${OpenCVParts_${_m}_LIBRARY}")
  endforeach()
endif()
