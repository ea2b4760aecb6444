#include "document.hpp"

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <limits>
#include <sstream>

namespace agvdyn::ff::detail {
namespace {

bool is_space(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n'; }

std::string trim(const std::string& s) {
  std::size_t a = 0, b = s.size();
  while (a < b && is_space(s[a])) ++a;
  while (b > a && is_space(s[b - 1])) --b;
  return s.substr(a, b - a);
}

std::string at_line(int line) { return line > 0 ? "line " + std::to_string(line) + ": " : ""; }

void append_utf8(std::string& out, unsigned long cp) {
  if (cp < 0x80) {
    out += static_cast<char>(cp);
  } else if (cp < 0x800) {
    out += static_cast<char>(0xC0 | (cp >> 6));
    out += static_cast<char>(0x80 | (cp & 0x3F));
  } else if (cp < 0x10000) {
    out += static_cast<char>(0xE0 | (cp >> 12));
    out += static_cast<char>(0x80 | ((cp >> 6) & 0x3F));
    out += static_cast<char>(0x80 | (cp & 0x3F));
  } else {
    out += static_cast<char>(0xF0 | (cp >> 18));
    out += static_cast<char>(0x80 | ((cp >> 12) & 0x3F));
    out += static_cast<char>(0x80 | ((cp >> 6) & 0x3F));
    out += static_cast<char>(0x80 | (cp & 0x3F));
  }
}

// --- flow collections: JSON and YAML flow style ----------------------------------------------

class FlowParser {
 public:
  FlowParser(const std::string& text, int first_line) : s_(text), line0_(first_line) {}

  bool parse(Node* out, std::string* error) {
    if (!value(out, false)) {
      *error = error_;
      return false;
    }
    skip();
    if (i_ != s_.size()) {
      *error = at_line(line()) + "unexpected '" + s_.substr(i_, 1) + "' after the value";
      return false;
    }
    return true;
  }

 private:
  int line() const {
    int n = line0_;
    for (std::size_t k = 0; k < i_ && k < s_.size(); ++k) n += s_[k] == '\n';
    return n;
  }
  bool fail(const std::string& what) {
    error_ = at_line(line()) + what;
    return false;
  }
  void skip() {
    while (i_ < s_.size()) {
      if (is_space(s_[i_])) {
        ++i_;
      } else if (s_[i_] == '#') {  // YAML comment (JSON has none)
        while (i_ < s_.size() && s_[i_] != '\n') ++i_;
      } else {
        break;
      }
    }
  }
  bool value(Node* out, bool in_mapping_key) {
    skip();
    out->line = line();
    if (i_ >= s_.size()) return fail("unexpected end of the document");
    const char c = s_[i_];
    if (c == '{') return mapping(out);
    if (c == '[') return sequence(out);
    if (c == '"') return double_quoted(out);
    if (c == '\'') return single_quoted(out);
    return plain(out, in_mapping_key);
  }
  bool mapping(Node* out) {
    out->kind = Node::Kind::mapping;
    ++i_;
    skip();
    if (i_ < s_.size() && s_[i_] == '}') {
      ++i_;
      return true;
    }
    while (true) {
      Node key;
      if (!value(&key, true)) return false;
      if (key.kind != Node::Kind::scalar) return fail("a mapping key must be a scalar");
      skip();
      Node val;
      if (i_ < s_.size() && s_[i_] == ':') {
        ++i_;
        skip();
        if (i_ < s_.size() && (s_[i_] == ',' || s_[i_] == '}')) {
          val.kind = Node::Kind::null;
        } else if (!value(&val, false)) {
          return false;
        }
      }
      out->keys.push_back(key.text);
      out->values.push_back(std::move(val));
      skip();
      if (i_ >= s_.size()) return fail("unterminated mapping: expected '}'");
      if (s_[i_] == ',') {
        ++i_;
        skip();
        if (i_ < s_.size() && s_[i_] == '}') {  // trailing comma (YAML allows it)
          ++i_;
          return true;
        }
        continue;
      }
      if (s_[i_] == '}') {
        ++i_;
        return true;
      }
      return fail("expected ',' or '}' in a mapping, found '" + s_.substr(i_, 1) + "'");
    }
  }
  bool sequence(Node* out) {
    out->kind = Node::Kind::sequence;
    ++i_;
    skip();
    if (i_ < s_.size() && s_[i_] == ']') {
      ++i_;
      return true;
    }
    while (true) {
      Node val;
      if (!value(&val, false)) return false;
      out->values.push_back(std::move(val));
      skip();
      if (i_ >= s_.size()) return fail("unterminated sequence: expected ']'");
      if (s_[i_] == ',') {
        ++i_;
        skip();
        if (i_ < s_.size() && s_[i_] == ']') {
          ++i_;
          return true;
        }
        continue;
      }
      if (s_[i_] == ']') {
        ++i_;
        return true;
      }
      return fail("expected ',' or ']' in a sequence, found '" + s_.substr(i_, 1) + "'");
    }
  }
  bool double_quoted(Node* out) {
    out->kind = Node::Kind::scalar;
    out->quoted = true;
    ++i_;
    std::string text;
    while (i_ < s_.size() && s_[i_] != '"') {
      char c = s_[i_++];
      if (c == '\n') {  // YAML line folding inside a quoted scalar
        while (!text.empty() && (text.back() == ' ' || text.back() == '\t')) text.pop_back();
        while (i_ < s_.size() && (s_[i_] == ' ' || s_[i_] == '\t')) ++i_;
        text += ' ';
        continue;
      }
      if (c != '\\') {
        text += c;
        continue;
      }
      if (i_ >= s_.size()) break;
      c = s_[i_++];
      switch (c) {
        case 'n': text += '\n'; break;
        case 't': text += '\t'; break;
        case 'r': text += '\r'; break;
        case 'b': text += '\b'; break;
        case 'f': text += '\f'; break;
        case '0': text += '\0'; break;
        case '/': case '\\': case '"': case '\'': case ' ': text += c; break;
        case '\n':  // escaped line break: nothing
          while (i_ < s_.size() && (s_[i_] == ' ' || s_[i_] == '\t')) ++i_;
          break;
        case 'x': case 'u': case 'U': {
          const int n = c == 'x' ? 2 : (c == 'u' ? 4 : 8);
          if (i_ + n > s_.size()) return fail("bad escape in a quoted string");
          char* end = nullptr;
          const std::string hex = s_.substr(i_, n);
          const unsigned long cp = std::strtoul(hex.c_str(), &end, 16);
          if (end != hex.c_str() + n) return fail("bad escape \\" + std::string(1, c) + hex);
          append_utf8(text, cp);
          i_ += n;
          break;
        }
        default: return fail(std::string("unknown escape \\") + c + " in a quoted string");
      }
    }
    if (i_ >= s_.size()) return fail("unterminated quoted string");
    ++i_;
    out->text = text;
    return true;
  }
  bool single_quoted(Node* out) {
    out->kind = Node::Kind::scalar;
    out->quoted = true;
    ++i_;
    std::string text;
    while (i_ < s_.size()) {
      const char c = s_[i_++];
      if (c == '\'') {
        if (i_ < s_.size() && s_[i_] == '\'') {
          text += '\'';
          ++i_;
          continue;
        }
        out->text = text;
        return true;
      }
      if (c == '\n') {
        while (!text.empty() && (text.back() == ' ' || text.back() == '\t')) text.pop_back();
        while (i_ < s_.size() && (s_[i_] == ' ' || s_[i_] == '\t')) ++i_;
        text += ' ';
        continue;
      }
      text += c;
    }
    return fail("unterminated quoted string");
  }
  bool plain(Node* out, bool in_mapping_key) {
    out->kind = Node::Kind::scalar;
    const std::size_t start = i_;
    while (i_ < s_.size()) {
      const char c = s_[i_];
      if (c == ',' || c == ']' || c == '}' || c == '\n') break;
      if (c == ':' && (i_ + 1 >= s_.size() || is_space(s_[i_ + 1]) || s_[i_ + 1] == ',' ||
                       (in_mapping_key && (s_[i_ + 1] == '"' || s_[i_ + 1] == '\'')))) {
        break;
      }
      if (c == '#' && i_ > start && is_space(s_[i_ - 1])) break;
      ++i_;
    }
    out->text = trim(s_.substr(start, i_ - start));
    if (out->text.empty()) return fail("expected a value");
    return true;
  }

  const std::string& s_;
  int line0_;
  std::size_t i_ = 0;
  std::string error_;
};

bool parse_flow(const std::string& text, int first_line, Node* out, std::string* error) {
  FlowParser p(text, first_line);
  return p.parse(out, error);
}

// --- YAML block style ------------------------------------------------------------------------

struct Line {
  int indent;
  std::string text;  // without indentation, comment and trailing blanks
  int number;        // 1-based
};

// Scan one line of YAML for the start of a comment (` #`) outside quoted scalars; `quote` is the
// quote open at the start of the line (0: none) and, on return, the one still open at its end. A
// quote opens a scalar only where a value starts: at the beginning, after `: `, `- `, `[`, `{`, `,`.
std::size_t scan_line(const std::string& s, char& quote) {
  bool value_start = true;
  for (std::size_t k = 0; k < s.size(); ++k) {
    const char c = s[k];
    if (quote) {
      if (quote == '"' && c == '\\') {
        ++k;
      } else if (c == quote) {
        if (quote == '\'' && k + 1 < s.size() && s[k + 1] == '\'') {
          ++k;
        } else {
          quote = 0;
          value_start = false;
        }
      }
      continue;
    }
    if (c == '#' && (k == 0 || is_space(s[k - 1]))) return k;
    if (is_space(c)) continue;
    if ((c == '"' || c == '\'') && value_start) {
      quote = c;
      continue;
    }
    if (c == '[' || c == '{' || c == ',') {
      value_start = true;
    } else if ((c == ':' || c == '-') && (k + 1 == s.size() || is_space(s[k + 1]))) {
      value_start = c == ':' || value_start;  // "- " keeps a value start only at one
    } else {
      value_start = false;
    }
  }
  return std::string::npos;
}

std::string rtrim(std::string s) {
  while (!s.empty() && is_space(s.back())) s.pop_back();
  return s;
}

bool is_sequence_item(const std::string& t) { return t == "-" || (t.size() > 1 && t[0] == '-' && t[1] == ' '); }

// Position of the ':' that ends a mapping key on this line, or npos.
std::size_t key_separator(const std::string& t) {
  if (t.empty() || t[0] == '[' || t[0] == '{') return std::string::npos;
  std::size_t k = 0;
  if (t[0] == '"' || t[0] == '\'') {  // quoted key
    const char q = t[0];
    for (k = 1; k < t.size(); ++k) {
      if (t[k] == '\\' && q == '"') {
        ++k;
        continue;
      }
      if (t[k] == q) {
        if (q == '\'' && k + 1 < t.size() && t[k + 1] == '\'') {
          ++k;
          continue;
        }
        break;
      }
    }
    ++k;
    while (k < t.size() && t[k] == ' ') ++k;
    if (k < t.size() && t[k] == ':' && (k + 1 == t.size() || t[k + 1] == ' ')) return k;
    return std::string::npos;
  }
  for (k = 0; k < t.size(); ++k) {
    if (t[k] == ':' && (k + 1 == t.size() || t[k + 1] == ' ')) return k;
  }
  return std::string::npos;
}

class BlockParser {
 public:
  explicit BlockParser(std::vector<Line> lines) : lines_(std::move(lines)) {}

  bool parse(Node* root, std::string* error) {
    if (lines_.empty()) {
      root->kind = Node::Kind::null;
      return true;
    }
    std::size_t i = 0;
    if (!node(i, lines_[0].indent, root)) {
      *error = error_;
      return false;
    }
    if (i < lines_.size()) {
      *error = at_line(lines_[i].number) + "unexpected indentation";
      return false;
    }
    return true;
  }

 private:
  bool fail(int line, const std::string& what) {
    error_ = at_line(line) + what;
    return false;
  }

  bool node(std::size_t& i, int indent, Node* out) {
    const Line& ln = lines_[i];
    out->line = ln.number;
    if (is_sequence_item(ln.text)) return sequence(i, indent, out);
    if (key_separator(ln.text) != std::string::npos) return mapping(i, indent, out);
    // a scalar or flow collection on its own line(s)
    return inline_value(i, indent - 1, ln.text, ln.number, out);
  }

  bool mapping(std::size_t& i, int indent, Node* out) {
    out->kind = Node::Kind::mapping;
    while (i < lines_.size() && lines_[i].indent == indent && !is_sequence_item(lines_[i].text)) {
      const Line ln = lines_[i];
      const std::size_t sep = key_separator(ln.text);
      if (sep == std::string::npos) return fail(ln.number, "expected 'key: value'");
      std::string key = trim(ln.text.substr(0, sep));
      if (!key.empty() && (key[0] == '"' || key[0] == '\'')) {
        Node k;
        std::string err;
        if (!parse_flow(key, ln.number, &k, &err)) return fail(0, err);
        key = k.text;
      }
      const std::string rest = trim(ln.text.substr(sep + 1));
      ++i;
      Node val;
      val.line = ln.number;
      if (rest.empty()) {
        if (i < lines_.size() && (lines_[i].indent > indent ||
                                  (lines_[i].indent == indent && is_sequence_item(lines_[i].text)))) {
          if (!node(i, lines_[i].indent, &val)) return false;
        }
      } else if (!inline_value(i, indent, rest, ln.number, &val)) {
        return false;
      }
      out->keys.push_back(key);
      out->values.push_back(std::move(val));
    }
    if (i < lines_.size() && lines_[i].indent > indent) return fail(lines_[i].number, "unexpected indentation");
    return true;
  }

  bool sequence(std::size_t& i, int indent, Node* out) {
    out->kind = Node::Kind::sequence;
    while (i < lines_.size() && lines_[i].indent == indent && is_sequence_item(lines_[i].text)) {
      Line& ln = lines_[i];
      std::size_t off = 1;
      while (off < ln.text.size() && ln.text[off] == ' ') ++off;
      Node val;
      val.line = ln.number;
      if (off >= ln.text.size()) {  // "-" alone: the item is on the next, deeper lines
        ++i;
        if (i < lines_.size() && lines_[i].indent > indent && !node(i, lines_[i].indent, &val)) return false;
      } else {  // "- rest": rest is a node at the column where it starts
        ln.indent += static_cast<int>(off);
        ln.text = ln.text.substr(off);
        if (!node(i, ln.indent, &val)) return false;
      }
      out->values.push_back(std::move(val));
    }
    return true;
  }

  // The value that starts on a line after "key:" or alone; continuation lines are those deeper
  // than `parent` (the indentation of the key).
  bool inline_value(std::size_t& i, int parent, const std::string& first, int number, Node* out) {
    std::string text = first;
    if (!text.empty() && text[0] == '&') {  // anchor: ignore its name
      const std::size_t sp = text.find(' ');
      text = sp == std::string::npos ? std::string() : trim(text.substr(sp + 1));
    }
    if (!text.empty() && (text[0] == '*' || text[0] == '!')) {
      return fail(number, "aliases and tags are not supported: '" + text + "'");
    }
    const bool started_here = i < lines_.size() && lines_[i].number == number;
    if (started_here) ++i;  // the first line is consumed
    auto more = [&]() { return i < lines_.size() && lines_[i].indent > parent; };
    if (!text.empty() && (text[0] == '|' || text[0] == '>')) {  // block scalar
      const bool literal = text[0] == '|';
      std::string body;
      while (more()) {
        if (!body.empty()) body += literal ? '\n' : ' ';
        body += lines_[i].text;
        ++i;
      }
      out->kind = Node::Kind::scalar;
      out->quoted = true;
      out->text = body;
      out->line = number;
      return true;
    }
    if (!text.empty() && (text[0] == '{' || text[0] == '[' || text[0] == '"' || text[0] == '\'')) {
      // flow collection or quoted scalar, possibly over several lines
      std::string err;
      while (true) {
        Node tmp;
        if (parse_flow(text, number, &tmp, &err)) {
          *out = std::move(tmp);
          return true;
        }
        if (!more()) return fail(0, err);
        text += '\n' + lines_[i].text;
        ++i;
      }
    }
    // plain scalar, folded over deeper lines
    while (more()) {
      text += ' ' + lines_[i].text;
      ++i;
    }
    out->kind = text.empty() ? Node::Kind::null : Node::Kind::scalar;
    out->text = text;
    out->line = number;
    return true;
  }

  std::vector<Line> lines_;
  std::string error_;
};

}  // namespace

const Node* Node::find(const std::string& key) const {
  if (kind != Kind::mapping) return nullptr;
  for (std::size_t k = 0; k < keys.size(); ++k) {
    if (keys[k] == key) return &values[k];
  }
  return nullptr;
}

bool Node::number(double* out) const {
  if (kind != Kind::scalar || quoted) return false;
  const std::string& t = text;
  if (t == ".inf" || t == ".Inf" || t == ".INF" || t == "+.inf" || t == "Infinity" || t == "+Infinity") {
    *out = std::numeric_limits<double>::infinity();
    return true;
  }
  if (t == "-.inf" || t == "-.Inf" || t == "-.INF" || t == "-Infinity") {
    *out = -std::numeric_limits<double>::infinity();
    return true;
  }
  if (t == ".nan" || t == ".NaN" || t == ".NAN" || t == "NaN") {
    *out = std::numeric_limits<double>::quiet_NaN();
    return true;
  }
  if (t.empty()) return false;
  for (char c : t) {  // decimal digits, sign, point, exponent only (no hex, no inf/nan words)
    if (!((c >= '0' && c <= '9') || c == '+' || c == '-' || c == '.' || c == 'e' || c == 'E')) return false;
  }
  char* end = nullptr;
  errno = 0;
  const double v = std::strtod(t.c_str(), &end);
  if (end != t.c_str() + t.size()) return false;
  *out = v;
  return true;
}

bool parse_document(const std::string& text, Node* root, std::string* error) {
  std::size_t k = 0;
  if (text.size() >= 3 && static_cast<unsigned char>(text[0]) == 0xEF && static_cast<unsigned char>(text[1]) == 0xBB &&
      static_cast<unsigned char>(text[2]) == 0xBF) {
    k = 3;  // UTF-8 byte order mark
  }
  std::size_t first = k;
  while (first < text.size() && is_space(text[first])) ++first;
  if (first < text.size() && (text[first] == '{' || text[first] == '[')) {
    int line = 1;
    for (std::size_t j = 0; j < first; ++j) line += text[j] == '\n';
    return parse_flow(text.substr(first), line, root, error);
  }
  std::vector<Line> lines;
  std::istringstream in(text.substr(k));
  std::string raw;
  int number = 0;
  char quote = 0;  // a quoted scalar continues over lines: they join its line
  while (std::getline(in, raw)) {
    ++number;
    if (!raw.empty() && raw.back() == '\r') raw.pop_back();
    if (quote) {
      std::size_t start = 0;
      while (start < raw.size() && (raw[start] == ' ' || raw[start] == '\t')) ++start;
      const std::string content = raw.substr(start);
      const std::size_t cut = scan_line(content, quote);
      lines.back().text += '\n' + rtrim(content.substr(0, cut));
      continue;
    }
    int indent = 0;
    while (indent < static_cast<int>(raw.size()) && raw[indent] == ' ') ++indent;
    if (indent < static_cast<int>(raw.size()) && raw[indent] == '\t') {
      *error = at_line(number) + "tab in the indentation: YAML indents with spaces";
      return false;
    }
    const std::string content = raw.substr(indent);
    const std::string t = rtrim(content.substr(0, scan_line(content, quote)));
    if (!quote && (t.empty() || t == "---" || t == "..." || t[0] == '%')) continue;
    lines.push_back({indent, t, number});
  }
  if (quote) {
    *error = at_line(lines.back().number) + "unterminated quoted string";
    return false;
  }
  BlockParser p(std::move(lines));
  return p.parse(root, error);
}

bool read_document(const std::string& path, Node* root, std::string* error) {
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    *error = path + ": cannot be read (" + std::strerror(errno) + ")";
    return false;
  }
  std::ostringstream buf;
  buf << in.rdbuf();
  std::string message;
  if (!parse_document(buf.str(), root, &message)) {
    *error = path + ": " + message;
    return false;
  }
  return true;
}

}  // namespace agvdyn::ff::detail
