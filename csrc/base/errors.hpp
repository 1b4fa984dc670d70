// errors.hpp - exception types the ABI door maps to hw_status codes (ConfigError lives in params.hpp).
#pragma once

#include <stdexcept>

namespace hw {

struct SourceError : std::runtime_error {  // a frame source cannot be opened -> HW_ERR_SOURCE
    using std::runtime_error::runtime_error;
};
struct StateError : std::runtime_error {   // call not allowed in this state -> HW_ERR_STATE
    using std::runtime_error::runtime_error;
};

} // namespace hw
