// A small reader of the data files agvdyn writes: JSON, and the block-style YAML subset that
// PyYAML's safe_dump emits (mappings, sequences, plain / quoted / folded scalars, flow
// collections such as `[]` or `{value: 1.0}`, comments). No anchors, tags or complex keys.
// Used once at start-up (parameter files, test vectors), never in a control loop.
#pragma once

#include <string>
#include <vector>

namespace agvdyn::ff::detail {

struct Node {
  enum class Kind { null, scalar, mapping, sequence };
  Kind kind = Kind::null;
  std::string text;              // scalar text, quotes removed
  bool quoted = false;           // a quoted scalar is a string, never a number
  std::vector<std::string> keys; // mapping keys, in file order
  std::vector<Node> values;      // mapping values (same index as keys) or sequence elements
  int line = 0;                  // 1-based line of the node in its file (0: unknown)

  bool is_mapping() const { return kind == Kind::mapping; }
  bool is_sequence() const { return kind == Kind::sequence; }
  bool is_null() const { return kind == Kind::null || (kind == Kind::scalar && !quoted && (text == "null" || text == "~" || text == "Null" || text == "NULL")); }
  /// Value of a mapping key, nullptr when absent or not a mapping.
  const Node* find(const std::string& key) const;
  /// The scalar as a number (JSON / YAML float syntax, .inf, .nan, NaN, Infinity); false otherwise.
  bool number(double* out) const;
};

/// Parse a JSON document (first non-blank character `{` or `[`) or a YAML block document.
/// False with a message naming the line on a syntax the reader does not know.
bool parse_document(const std::string& text, Node* root, std::string* error);

/// Read and parse a file; the message starts with the path.
bool read_document(const std::string& path, Node* root, std::string* error);

}  // namespace agvdyn::ff::detail
