#include "lmrefine/core/error.h"

#include <cstring>

namespace lmrefine::detail {

std::string with_location(const std::string& message, const char* file, int line) {
    const char* base = std::strrchr(file, '/');
    return message + " [" + (base ? base + 1 : file) + ":" + std::to_string(line) + "]";
}

}  // namespace lmrefine::detail
