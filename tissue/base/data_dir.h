#pragma once
// Where the phantom catalogue and other shipped data live, found at run time so that
// nothing compiled in points at the source tree:
//   1. $SONOTRACE_DATA, if set (a directory holding phantoms/);
//   2. <the executable's directory>/../share/sonotrace (an installed prefix);
//   3. the directory named in <the executable's directory>/sonotrace-source-dir, which a
//      build tree holds (CMake writes it; it is not installed);
//   4. the current directory.
#include <string>

namespace sonotrace::base {

std::string data_dir();
// data_dir() + "/phantoms".
std::string phantom_catalogue_dir();

}  // namespace sonotrace::base
