#!/usr/bin/env bash
# logdiff.sh BEFORE_RUN AFTER_RUN: the two runs' fit.log less clocks (stamps, training seconds, kernel and
# identifiability seconds), run paths and this branch's new clocked lines; prints "equal" or the diff
norm() {
  sed 's/^\[ *[0-9.]* s\] //' "$1/fit.log" | grep -v "^start: imports" \
    | sed -E "s#$1#RUN#g; s/ in [0-9.]+ s:/ in S s:/; s/done in [0-9.]+ s \(.*\)/done in S s/; s/done at [0-9.]+ s/done at S s/; \
s/  [0-9]+s$/  Ns/; s/^done: [0-9]+ s of training \(identification [0-9]+ s \+ residual [0-9]+ s\)/done: N s of training/"
}
diff <(norm "$1") <(norm "$2") && echo "fit.log: equal less clocks and run paths ($(wc -l < "$1/fit.log") lines)"
