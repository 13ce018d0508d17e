#!/usr/bin/env bash
# Send one path to a Teleworkbench robot agent over TCP with bash's /dev/tcp, and follow it.
#
#   twb plan --env room --plan A --planner fm2 --format ttp | examples/shell_planner/send_path.sh 127.0.0.1 5555
#   examples/shell_planner/send_path.sh 127.0.0.1 5555 "T,T,P,100,100,0;500,100,90;500,600,90"
#
# Prints the greeting, the reply and every event; exit 0 on EV,DONE, 1 on ERR or EV,FAIL,
# 2 on a usage or connection error.  Needs bash (for /dev/tcp), nothing else.
set -u
host=${1:?usage: send_path.sh HOST PORT [T,T,P-line]   (or the line on stdin)}
port=${2:?usage: send_path.sh HOST PORT [T,T,P-line]}
line=${3:-$(head -n 1)}
case $line in T,T,P,*) ;; *) echo "not a T,T,P line: ${line:0:40}" >&2; exit 2 ;; esac

exec 3<>"/dev/tcp/$host/$port" || { echo "cannot connect to $host:$port" >&2; exit 2; }
IFS= read -r -t 10 hello <&3 || { echo "no greeting from $host:$port" >&2; exit 2; }
echo "${hello%$'\r'}"
printf '%s\n' "$line" >&3
while IFS= read -r -t "${FOLLOW_TIMEOUT:-600}" reply <&3; do
    reply=${reply%$'\r'}
    echo "$reply"
    case $reply in
        ERR,*|EV,FAIL,*) exec 3>&-; exit 1 ;;
        EV,DONE,*) exec 3>&-; exit 0 ;;
    esac
done
echo "connection closed or timed out before EV,DONE" >&2
exit 1
