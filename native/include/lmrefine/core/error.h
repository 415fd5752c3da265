// One error hierarchy for the core; the bindings map each type to one Python
// exception (InvalidArgument -> ValueError, IoError -> OSError,
// ResourceError -> MemoryError, Cancelled -> lmrefine.CancelledError).
#pragma once

#include <stdexcept>
#include <string>

namespace lmrefine {

class Error : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

// Bad input from the caller: the message names the problem and the fix.
class InvalidArgument : public Error {
public:
    using Error::Error;
};

// A file could not be read or written; the message names the file.
class IoError : public Error {
public:
    using Error::Error;
};

// A request that would need more memory than is sensible (checked before allocating).
class ResourceError : public Error {
public:
    using Error::Error;
};

// The user cancelled a long call (progress callback returned False, Ctrl-C, Esc).
class Cancelled : public Error {
public:
    Cancelled() : Error("cancelled") {}
};

namespace detail {
std::string with_location(const std::string& message, const char* file, int line);
}  // namespace detail

}  // namespace lmrefine

// Throws `Type` with the message and the native source location, so a report
// from a user points at the check that fired.
#define LMREFINE_THROW(Type, message) \
    throw Type(::lmrefine::detail::with_location((message), __FILE__, __LINE__))

#define LMREFINE_REQUIRE(condition, message)                          \
    do {                                                              \
        if (!(condition)) LMREFINE_THROW(::lmrefine::InvalidArgument, message); \
    } while (0)
