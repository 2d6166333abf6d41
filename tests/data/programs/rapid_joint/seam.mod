MODULE seam
  ! golden path
  CONST speeddata v_lt:=[100.000,28.648,5000,1000];
  CONST zonedata z_lt:=[FALSE,1.000,1.500,1.500,0.150,1.500,0.150];
  CONST jointtarget j1:=[[0.0000,0.0000,0.0000,0.0000,90.0000,0.0000],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST jointtarget j2:=[[15.0000,0.0000,0.0000,0.0000,90.0000,0.0000],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST jointtarget j3:=[[30.0000,0.0000,0.0000,0.0000,90.0000,0.0000],[9E9,9E9,9E9,9E9,9E9,9E9]];
  PROC main()
    ConfJ \On;
    ConfL \On;
    ! P1
    MoveAbsJ j1,v100,fine,tool0;
    MoveAbsJ j2,v_lt,z_lt,tool0;
    ! P2
    MoveAbsJ j3,v_lt,fine,tool0;
  ENDPROC
ENDMODULE
