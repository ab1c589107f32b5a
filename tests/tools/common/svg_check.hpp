// Small SVG inspection helpers for the plot tests: an XML well-formedness check (balanced,
// properly nested tags, quoted attributes, valid entities) and element/attribute extraction.
#pragma once

#include <cstddef>
#include <string>
#include <string_view>
#include <vector>

namespace svgcheck {

struct Element {
  std::string name;  // tag name
  std::string tag;   // the whole start tag text "<name ...>"
  std::string text;  // character data directly after the start tag (up to the next '<')
};

// Empty string if `doc` is well formed, otherwise what is wrong and where.
inline std::string well_formed(std::string_view doc) {
  std::vector<std::string> stack;
  std::size_t i = 0;
  bool root_seen = false;
  while (i < doc.size()) {
    const char c = doc[i];
    if (c == '&') {
      const std::size_t semi = doc.find(';', i);
      const std::string_view ent = doc.substr(i, semi == std::string_view::npos ? 8 : semi - i + 1);
      if (ent != "&amp;" && ent != "&lt;" && ent != "&gt;" && ent != "&quot;" && ent != "&apos;") {
        return "bad entity '" + std::string(ent) + "' at " + std::to_string(i);
      }
      i = semi + 1;
      continue;
    }
    if (c != '<') {
      if (c == '>') return "stray '>' at " + std::to_string(i);
      ++i;
      continue;
    }
    if (doc.substr(i, 2) == "<?") {
      const std::size_t e = doc.find("?>", i);
      if (e == std::string_view::npos) return "unterminated <?";
      i = e + 2;
      continue;
    }
    if (doc.substr(i, 4) == "<!--") {
      const std::size_t e = doc.find("-->", i);
      if (e == std::string_view::npos) return "unterminated comment";
      i = e + 3;
      continue;
    }
    // find the end of the tag, honouring quoted attribute values
    std::size_t j = i + 1;
    char quote = 0;
    for (; j < doc.size(); ++j) {
      if (quote) {
        if (doc[j] == quote) quote = 0;
        else if (doc[j] == '<') return "'<' inside an attribute value at " + std::to_string(j);
      } else if (doc[j] == '"' || doc[j] == '\'') {
        quote = doc[j];
      } else if (doc[j] == '>') {
        break;
      } else if (doc[j] == '<') {
        return "'<' inside a tag at " + std::to_string(j);
      }
    }
    if (j >= doc.size()) return "unterminated tag at " + std::to_string(i);
    const std::string_view tag = doc.substr(i, j - i + 1);
    if (tag.size() > 1 && tag[1] == '/') {
      const std::string name(tag.substr(2, tag.size() - 3));
      if (stack.empty()) return "closing </" + name + "> without an open tag";
      if (stack.back() != name) return "closing </" + name + "> but <" + stack.back() + "> is open";
      stack.pop_back();
    } else {
      std::size_t k = 1;
      while (k < tag.size() && tag[k] != ' ' && tag[k] != '>' && tag[k] != '/' && tag[k] != '\n') ++k;
      const std::string name(tag.substr(1, k - 1));
      if (name.empty()) return "empty tag name at " + std::to_string(i);
      const bool self_closing = tag[tag.size() - 2] == '/';
      if (stack.empty()) {
        if (root_seen) return "second root element <" + name + ">";
        root_seen = true;
      }
      if (!self_closing) stack.push_back(name);
    }
    i = j + 1;
  }
  if (!stack.empty()) return "unclosed <" + stack.back() + ">";
  if (!root_seen) return "no root element";
  return {};
}

// Every start tag of element `name` (e.g. "path") whose start tag contains `must_contain`.
inline std::vector<Element> elements(std::string_view doc, std::string_view name,
                                     std::string_view must_contain = "") {
  std::vector<Element> out;
  const std::string open = "<" + std::string(name);
  std::size_t i = 0;
  while ((i = doc.find(open, i)) != std::string_view::npos) {
    const char after = doc[i + open.size()];
    if (after != ' ' && after != '>' && after != '/') {
      i += open.size();
      continue;
    }
    const std::size_t e = doc.find('>', i);
    Element el;
    el.name = std::string(name);
    el.tag = std::string(doc.substr(i, e - i + 1));
    const std::size_t t_end = doc.find('<', e);
    el.text = std::string(doc.substr(e + 1, t_end - e - 1));
    if (must_contain.empty() || el.tag.find(must_contain) != std::string::npos) out.push_back(std::move(el));
    i = e;
  }
  return out;
}

// Value of attribute `attr` in a start tag ("" when absent).
inline std::string attr(std::string_view tag, std::string_view a) {
  const std::string key = " " + std::string(a) + "=\"";
  const std::size_t p = tag.find(key);
  if (p == std::string_view::npos) return {};
  const std::size_t s = p + key.size();
  return std::string(tag.substr(s, tag.find('"', s) - s));
}

// Number of subpaths (move-to commands) in a path's d attribute.
inline std::size_t subpaths(std::string_view d) {
  std::size_t n = 0;
  for (char c : d) n += (c == 'M') ? 1 : 0;
  return n;
}

inline std::size_t count(std::string_view doc, std::string_view needle) {
  std::size_t n = 0;
  for (std::size_t i = doc.find(needle); i != std::string_view::npos; i = doc.find(needle, i + 1)) ++n;
  return n;
}

}  // namespace svgcheck
