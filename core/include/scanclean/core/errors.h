#pragma once
//! \file errors.h
//! The project's error rule (STYLE.md practice 4), written down once:
//!  - programming errors (broken invariants) -> assert();
//!  - bad input (files, recordings, captures), bad options, I/O failures and unavailable devices
//!    -> the typed exceptions below, each with a message that names the file, the place and what
//!    was expected;
//!  - expected runtime outcomes of a stream (timeout, end of stream, disconnect) -> return values
//!    (scanclean::ReadStatus), never exceptions.
//! The command-line program maps each exception type to a documented exit code (exit_code_for).

#include <cstdint>
#include <exception>
#include <stdexcept>
#include <string>

namespace scanclean {

//! Base of every scanclean exception.
class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

//! Malformed, inconsistent or unsupported input data (a file, a recording, a capture).
class InputError : public Error {
 public:
  using Error::Error;
  //! Message "<file>: <place>: <what>", e.g. "bun.ply: line 12: expected 3 numbers, got 2".
  InputError(const std::string& file, const std::string& place, const std::string& what);
};

//! An option or parameter out of its valid range.
class OptionError : public Error {
 public:
  using Error::Error;
};

//! The operating system refused an operation (open, read, write, rename).
class IoError : public Error {
 public:
  using Error::Error;
};

//! No device, device busy, driver missing, or a feature not compiled into this build.
class UnavailableError : public Error {
 public:
  using Error::Error;
};

//! Process exit codes that scripts can rely on.
enum class ExitCode : int {
  kOk = 0,            //!< success
  kFailure = 1,       //!< unexpected internal error
  kBadOptions = 2,    //!< invalid command line or option value
  kBadInput = 3,      //!< malformed or unsupported input data
  kIoFailure = 4,     //!< cannot read or write a file
  kUnavailable = 5,   //!< no device / driver / feature
  kEmptyResult = 6,   //!< the result is empty or collapsed (<= 1 point from more); not written
  kInterrupted = 130  //!< stopped by SIGINT (recordings stay valid up to the last frame)
};

//! The exit code documented for an exception of this type.
ExitCode exit_code_for(const std::exception& e) noexcept;

//! Helper for byte offsets in messages: "byte 1234".
std::string byte_place(std::uint64_t offset);
//! Helper for line numbers in messages: "line 12".
std::string line_place(std::uint64_t line);

}  // namespace scanclean
