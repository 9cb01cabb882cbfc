#pragma once
// Told the stages of a long preparation (loading, binding, placing): the CLI times and
// prints them, the GUI and the tests pass none.
#include <string>

namespace sonotrace::base {

class StageObserver {
  public:
    virtual ~StageObserver() = default;
    virtual void begin(const std::string& stage) = 0;
    virtual void end() = 0;
};

}  // namespace sonotrace::base
