// O-word control flow with LinuxCNC 2.9 semantics (interp_o_word.cc): labels recorded in an
// offset map when first read, "skipping" forward to a label, jumps back to a loop head, a call
// stack with #1..#30 arguments saved and restored and local named parameters per call.
// Labels other than sub/endsub/call/return are local to the subroutine they are in
// ("<sub>#<label>"); reusing a label at the same level is an error, as in LinuxCNC; so is a
// subroutine definition reached after the subroutine was called before its definition.
#include <algorithm>
#include <cmath>

#include "control/gcode_interp.hpp"

namespace contour::control::gcode_detail {

Label* Interpreter::control_find_oword(const std::string& name) {
  const auto it = offset_map_.find(name);
  return it == offset_map_.end() ? nullptr : &it->second;
}

void Interpreter::control_save_offset() {
  const int col = blk_.o_col;
  if (const Label* op = control_find_oword(blk_.o_name)) {
    if (sequence_ == op->line) fail(col, "o<" + blk_.o_name + "> sub found where it cannot be defined (it was called before its definition)");
    fail(col, "o<" + blk_.o_name + "> is already defined (line " + std::to_string(op->line) + " of " +
                  sources_[static_cast<std::size_t>(op->source)].name + ")");
  }
  Label l;
  l.type = blk_.o_type;
  l.source = cur_source_;
  l.line = sequence_;
  offset_map_[blk_.o_name] = l;
}

void Interpreter::jump_to(int source, int line) {
  cur_source_ = source;
  cur_line_ = line;
}

int Interpreter::load_sub_file(const std::string& name) {
  const std::string file = name + ".ngc";
  for (std::size_t i = 1; i < sources_.size(); ++i)
    if (!sources_[i].mdi && sources_[i].name == file && sources_[i].first_line == 1) return static_cast<int>(i);
  if (!setup_.load_subroutine) return -1;
  const std::optional<std::string> text = setup_.load_subroutine(name);
  if (!text) return -1;
  Source s;
  s.name = file;
  std::size_t pos = 0;
  const std::string& t = *text;
  while (pos < t.size()) {
    std::size_t nl = t.find('\n', pos);
    if (nl == std::string::npos) nl = t.size();
    s.lines.emplace_back(t.substr(pos, nl - pos));
    pos = nl + 1;
  }
  s.eof = true;
  sources_.push_back(std::move(s));
  return static_cast<int>(sources_.size()) - 1;
}

// LinuxCNC's control_back_to: a known label (jump to its line), else a subroutine file, else skip
// forward in the current source to the label.
void Interpreter::control_back_to(const std::string& name) {
  if (const Label* op = control_find_oword(name)) {
    jump_to(op->source, op->line);
    return;
  }
  const int f = load_sub_file(name);
  if (f >= 0) jump_to(f, 1);
  skipping_o_ = name;
  skipping_ = true;
  skipping_to_sub_ = name;
  skipping_to_sub_on_ = true;
  skipping_start_ = sequence_;
}

void Interpreter::execute_call() {
  if (frames_.size() >= static_cast<std::size_t>(kMaxCallLevel))
    fail(blk_.o_col, "too many nested subroutine calls (at most " + std::to_string(kMaxCallLevel - 1) + ")");
  skipping_ = false;
  CallFrame f;
  f.sub_name = blk_.o_name;
  f.return_source = cur_source_;
  f.return_line = cur_line_;
  for (int i = 0; i < kSubParams; ++i) {
    f.saved_params[static_cast<std::size_t>(i)] = params_[static_cast<std::size_t>(i + 1)];
    params_[static_cast<std::size_t>(i + 1)] = blk_.params[static_cast<std::size_t>(i)];
  }
  frames_.push_back(std::move(f));
  control_back_to(blk_.o_name);
}

void Interpreter::execute_return() {
  if (skipping_ && blk_.o_type == OType::kEndsub) skipping_ = false;
  if (frames_.size() > 1) {
    CallFrame& f = frames_.back();
    for (int i = 0; i < kSubParams; ++i)
      params_[static_cast<std::size_t>(i + 1)] = f.saved_params[static_cast<std::size_t>(i)];
    jump_to(f.return_source, f.return_line);
    frames_.pop_back();
    return;
  }
  if (blk_.o_type != OType::kEndsub) return;
  if (!defining_sub_) fail(blk_.o_col, "o<" + blk_.o_name + "> endsub outside a subroutine definition");
  skipping_ = false;
  defining_sub_ = false;
  // A subroutine defined in the main program: keep its lines in a source of their own so the
  // program's lines can be dropped as it streams.
  Label* op = control_find_oword(sub_name_);
  if (op != nullptr && op->source == 0 && cur_source_ == 0) {
    const Source& m = sources_[0];
    Source s;
    s.name = m.name;
    s.first_line = op->line;
    for (int l = op->line; l <= sequence_; ++l) s.lines.push_back(m.at(l));
    s.eof = true;
    sources_.push_back(std::move(s));
    op->source = static_cast<int>(sources_.size()) - 1;
  }
  sub_name_.clear();
  defining_line_ = 0;
}

void Interpreter::convert_control_functions() {
  const std::string& name = blk_.o_name;
  if (skipping_ && skipping_o_ != name) return;
  if (skipping_to_sub_on_ && blk_.o_type != OType::kSub) return;
  const int col = blk_.o_col;
  const auto undefined = [&]() { fail(col, "undefined O-word label o" + name.substr(name.find('#') + 1)); };
  const auto label_text = [&]() { return "o" + name.substr(name.find('#') + 1); };
  // Loops in the main program: remember where they end so their lines can be dropped afterwards.
  const auto mark_end = [&](Label* op) {
    if (op != nullptr && op->source == cur_source_ && sequence_ > op->end_line) op->end_line = sequence_;
  };
  switch (blk_.o_type) {
    case OType::kNone:
      break;
    case OType::kSub:
      if (skipping_) {
        control_save_offset();
        skipping_ = false;
      }
      skipping_to_sub_on_ = false;
      if (frames_.size() > 1) break;  // reached by a call: run the body
      if (defining_sub_) fail(col, "nested subroutine definition");
      control_save_offset();
      skipping_o_ = name;
      skipping_ = true;
      skipping_start_ = sequence_;
      defining_sub_ = true;
      sub_name_ = name;
      defining_line_ = sequence_;
      break;
    case OType::kEndsub:
    case OType::kReturn:
      if (frames_.size() == 1 && sub_name_.empty())
        fail(col, "o<" + name + "> " + (blk_.o_type == OType::kEndsub ? "endsub" : "return") +
                      " outside a subroutine");
      execute_return();
      break;
    case OType::kCall:
      execute_call();
      break;
    case OType::kDo:
      skipping_ = false;
      if (control_find_oword(name) == nullptr) control_save_offset();
      break;
    case OType::kRepeat: {
      if (const Label* op = control_find_oword(name)) {
        if (sequence_ != op->line)
          fail(col, "duplicate O-word label " + label_text() + " (defined at line " + std::to_string(op->line) + ")");
      } else {
        control_save_offset();
      }
      skipping_ = false;
      Label* op = control_find_oword(name);
      if (op->repeat_count == -1) op->repeat_count = static_cast<int>(std::nearbyint(std::clamp(test_value_, -2e9, 2e9)));
      if (op->repeat_count > 0) {
        --op->repeat_count;
      } else {
        skipping_o_ = name;
        skipping_ = true;
        skipping_start_ = sequence_;
        op->repeat_count = -1;
      }
      break;
    }
    case OType::kWhile: {
      if (const Label* op = control_find_oword(name)) {
        if (op->type != OType::kDo && sequence_ != op->line)
          fail(col, "duplicate O-word label " + label_text() + " (defined at line " + std::to_string(op->line) + ")");
      } else {
        control_save_offset();
      }
      skipping_ = false;
      Label* op = control_find_oword(name);
      if (op->type == OType::kWhile) {
        if (test_value_ == 0.0) {
          skipping_o_ = name;
          skipping_ = true;
          skipping_start_ = sequence_;
        }
      } else {  // the end of a do ... while
        mark_end(op);
        if (test_value_ != 0.0 && !doing_break_) {
          control_back_to(name);
        } else {
          doing_break_ = false;
        }
      }
      break;
    }
    case OType::kIf:
      if (const Label* op = control_find_oword(name)) {
        if (sequence_ != op->line)
          fail(col, "duplicate O-word label " + label_text() + " (defined at line " + std::to_string(op->line) + ")");
      } else {
        control_save_offset();
      }
      if (test_value_ != 0.0) {
        skipping_ = false;
        executed_if_ = true;
      } else {
        skipping_o_ = name;
        skipping_ = true;
        skipping_start_ = sequence_;
        executed_if_ = false;
      }
      break;
    case OType::kElseif: {
      const Label* op = control_find_oword(name);
      if (op == nullptr) undefined();
      if (op->type != OType::kIf) fail(col, "elseif without a matching if " + label_text());
      if (executed_if_) {
        skipping_o_ = name;
        skipping_ = true;
        skipping_start_ = sequence_;
        break;
      }
      if (test_value_ != 0.0) {
        skipping_ = false;
        executed_if_ = true;
      }
      break;
    }
    case OType::kElse: {
      const Label* op = control_find_oword(name);
      if (op == nullptr) undefined();
      if (op->type != OType::kIf) fail(col, "else without a matching if " + label_text());
      if (executed_if_) {
        skipping_o_ = name;
        skipping_ = true;
        skipping_start_ = sequence_;
        break;
      }
      if (skipping_ && skipping_o_ == name) {
        executed_if_ = true;
        skipping_ = false;
      }
      break;
    }
    case OType::kEndif: {
      const Label* op = control_find_oword(name);
      if (op == nullptr) undefined();
      if (op->type != OType::kIf) fail(col, "endif without a matching if " + label_text());
      skipping_ = false;
      executed_if_ = true;
      break;
    }
    case OType::kBreak:
    case OType::kContinue: {
      const Label* op = control_find_oword(name);
      if (op == nullptr) undefined();
      if (op->type != OType::kWhile && op->type != OType::kDo)
        fail(col, std::string(blk_.o_type == OType::kBreak ? "break" : "continue") +
                      " without a matching while/do " + label_text());
      if (blk_.o_type == OType::kBreak) {
        skipping_o_ = name;
        skipping_ = true;
        skipping_start_ = sequence_;
        doing_break_ = true;
      } else {
        if (skipping_ && skipping_o_ == name) break;
        skipping_o_ = name;
        skipping_ = true;
        skipping_start_ = sequence_;
        doing_continue_ = true;
      }
      break;
    }
    case OType::kEndwhile:
    case OType::kEndrepeat: {
      Label* op = control_find_oword(name);
      if (op == nullptr) undefined();
      if ((blk_.o_type == OType::kEndrepeat && op->type != OType::kRepeat) ||
          (blk_.o_type == OType::kEndwhile && op->type != OType::kWhile))
        fail(col, std::string(blk_.o_type == OType::kEndwhile ? "endwhile" : "endrepeat") +
                      " without a matching " + (blk_.o_type == OType::kEndwhile ? "while " : "repeat ") + label_text());
      mark_end(op);
      if (skipping_ && skipping_o_ == name) {
        skipping_ = false;
        if (doing_continue_) {
          doing_continue_ = false;
          control_back_to(name);
        }
      } else {
        control_back_to(name);
      }
      break;
    }
  }
}

}  // namespace contour::control::gcode_detail
