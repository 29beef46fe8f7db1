// Files that a flag names (TLS certificates and keys, bearer tokens): read whole, with errors
// that name the flag and the path, worded the same in catgs-server and catgs-client.
#pragma once

#include <string>

namespace catgs {

/// The whole file, as bytes: a regular file of at most kMaxSmallFileBytes. Throws
/// catgs::Error "FLAG 'PATH': cannot read the file: REASON".
std::string read_file(const std::string& path, const std::string& flag);

/// A bearer token: the file's first line without trailing blanks and carriage return.
/// Throws catgs::Error naming --token-file and the path when the file cannot be read or the
/// first line is empty.
std::string read_token(const std::string& path);

}  // namespace catgs
